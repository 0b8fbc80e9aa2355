// Fuzzes the rig bus (thesis A.1) through the harness every protocol shares
// (protocol_fuzz_template.hpp): one input to the message and report
// decoders, the input as a stream of reports and messages (and again with
// CRCs recomputed, so mutations reach the field checks), fed to the host's
// RigBusHost and topology tracker, and to a component's relay step (check,
// fill the parent, re-seal). Seeds: corpus/rig_bus_protocol/ (regenerate with
// PROPRIO_REGEN_CORPUS=1, see tests/unit/input/rig_bus/test_bus_protocol.cpp).
// Frames take the size their first byte gives (a report ID or a message's
// type byte); anything else takes 64 bytes.
#include <algorithm>
#include <cmath>

#include "proprio/rig_bus/bus_host.hpp"
#include "proprio/rig_bus/bus_protocol.hpp"
#include "protocol_fuzz_template.hpp"

namespace {

using namespace proprio;
using namespace proprio::rig_bus;
using fuzz::require;

void check_message_fields(const BusMessage& m) {
  require(m.creator_id != kNoComponent && m.creator_id != m.parent_id);
  require(m.parent_id == kNoComponent ? m.parent_outlet == kNoOutlet : m.parent_outlet < kMaxOutlets);
  switch (m.type) {
    case BusMessageType::data: {
      for (const std::int16_t a : m.data.angles_cdeg) require(a >= -kMaxAngleCentideg && a <= kMaxAngleCentideg);
      const rig_device::JointAngles a = angles_from_wire(m.data);
      require(std::isfinite(a.twist_in_rad) && std::abs(a.bend_x_rad) <= 3.1416);
      // What the host reads back quantises to the same counts.
      require(quantise_angles(a) == m.data);
      break;
    }
    case BusMessageType::type:
      require(m.type_info.outlet_count >= 1 && m.type_info.outlet_count <= kMaxOutlets);
      require(kind_name_of(m.type_info).size() <= kKindNameBytes);
      break;
    case BusMessageType::child:
      require(m.child.outlet < m.child.outlet_count && m.child.outlet_count <= kMaxOutlets);
      require(std::abs(rotation_from_wire(m.child.q_wxyz).norm() - 1.0) < 1e-9);
      break;
  }
}

// A component's firmware on a message from its outlet 3: check, fill an
// empty parent, re-seal; the result decodes to the same message, parent filled.
void check_relay(const BusMessage& m) {
  if (m.parent_id != kNoComponent || m.creator_id == 0xA5A5A5A5u) return;
  BusMessage filled = m;
  filled.parent_id = 0xA5A5A5A5u;
  filled.parent_outlet = 3;
  const auto bytes = encode_bus_message(filled);
  BusMessage back;
  require(decode_bus_message(bytes, back).ok() && back == filled);
}

void check_tracker(const RigBusHost& host, TimeNs now) {
  const BusTopologyTracker& t = host.tracker();
  const BusSnapshot s = t.snapshot(now);
  require(s.components.size() <= t.options().max_components);
  require(std::is_sorted(s.components.begin(), s.components.end(),
                         [](const BusComponentView& a, const BusComponentView& b) { return a.id < b.id; }));
  std::size_t attached = 0;
  for (const BusComponentView& v : s.components) {
    require(v.silent_ns >= 0 && v.outlets.size() <= kMaxOutlets);
    if (!v.attached) continue;
    ++attached;
    // An attached component's parent chain is attached up to the base.
    if (v.parent_id == kNoComponent) {
      require(v.id == s.base_id);
    } else {
      const BusComponentView* p = s.find(v.parent_id);
      require(p != nullptr && p->attached);
    }
  }
  require(attached == s.attached);
  require(t.attached_edges(now).size() == attached);
  const RigBusHostStats st = host.stats();
  require(st.decode_errors <= st.reports && fuzz::sum(st.decode_errors_by_code) == st.decode_errors);
  // Messages reach the tracker from reports and, in this harness, directly.
  require(st.tracker.messages + st.tracker.table_full >= st.messages);
}

struct RigBusProtocol {
  static constexpr std::size_t kMaxFrames = 4096;
  static constexpr bool kFixCrcOfShortFrames = true;
  static std::size_t frame_size(std::uint8_t first) {
    if (const std::size_t r = rig_bus_report_size_for_id(first)) return r;
    if (const std::size_t m = bus_message_size(first)) return m;
    return kRigBusReportSize;
  }

  static void check_reports(std::span<const std::uint8_t> bytes) {
    fuzz::check_form<BusMessage>(
        bytes, [](auto b, auto& v) { return decode_bus_message(b, v); },
        [](const BusMessage& v) { return encode_bus_message(v); }, fuzz::OnReject::leaves_untouched,
        [](const BusMessage& m) {
          check_message_fields(m);
          check_relay(m);
        });
    fuzz::check_form<RigBusReport>(
        bytes, [](auto b, auto& v) { return decode_rig_bus_report(b, v); },
        [](const RigBusReport& v) { return encode_rig_bus_report(v); }, fuzz::OnReject::leaves_untouched,
        [](const RigBusReport& r) {
          require(r.count <= kRigBusMaxMessagesPerReport);
          for (std::size_t i = 0; i < r.count; ++i) check_message_fields(r.messages[i]);
          for (std::size_t i = r.count; i < r.messages.size(); ++i) require(r.messages[i] == BusMessage{});
        });
  }

  static void check_streams(const fuzz::Frames& frames, bool) {
    BusTrackerOptions o;
    o.max_components = 16;  // small, so floods of IDs reach the eviction
    o.detach_after_ns = 50 * kNsPerMillisecond;
    RigBusHost host(o);
    TimeNs now = 0;
    for (const fuzz::Frame& f : frames) {
      const std::uint32_t gap_us = f.size() >= 2 ? static_cast<std::uint32_t>(f[f.size() - 2] | f[f.size() - 1] << 8) : 1;
      now += static_cast<TimeNs>(gap_us) * 1000;
      if (!f.empty() && f[0] == kRigBusReportId) {
        (void)host.on_report(f, now);
      } else {
        BusMessage m;
        if (decode_bus_message(f, m)) host.tracker().on_message(m, now);
      }
      host.update(now);
    }
    check_tracker(host, now);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return proprio::fuzz::fuzz_protocol<RigBusProtocol>(data, size);
}
