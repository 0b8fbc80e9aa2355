#include "proprio/rig_bus/bus_host.hpp"

#include <algorithm>
#include <cstdio>

namespace proprio::rig_bus {

Status BusTrackerOptions::validate() const {
  if (detach_after_ns <= 0) {
    return make_error(Errc::invalid_argument,
                      "BusTrackerOptions.detach_after_ns must be positive (the thesis's silence is 2 s)");
  }
  if (max_components < 2) {
    return make_error(Errc::invalid_argument, "BusTrackerOptions.max_components must be at least 2 (a base and one joint)");
  }
  return {};
}

std::string BusTrackerOptions::describe() const {
  char text[160];
  std::snprintf(text, sizeof text, "detach after %.0f ms of silence, at most %zu components",
                static_cast<double>(detach_after_ns) * 1e-6, max_components);
  return text;
}

const BusComponentView* BusSnapshot::find(std::uint32_t id) const {
  const auto it = std::lower_bound(components.begin(), components.end(), id,
                                   [](const BusComponentView& c, std::uint32_t v) { return c.id < v; });
  return it != components.end() && it->id == id ? &*it : nullptr;
}

BusTopologyTracker::BusTopologyTracker(BusTrackerOptions options) : options_(options) {
  if (!options_.validate()) options_ = BusTrackerOptions{};
  table_.reserve(std::min<std::size_t>(options_.max_components, 64));
}

BusTopologyTracker::Entry* BusTopologyTracker::entry_for(std::uint32_t id, TimeNs now_ns) {
  if (auto it = table_.find(id); it != table_.end()) return &it->second;
  if (table_.size() >= options_.max_components) {
    const auto attached = attached_at(now_ns);
    auto victim = table_.end();
    for (auto it = table_.begin(); it != table_.end(); ++it) {
      if (attached.at(it->first)) continue;
      if (victim == table_.end() || it->second.last_seen_ns < victim->second.last_seen_ns) victim = it;
    }
    if (victim == table_.end()) {
      ++stats_.table_full;
      return nullptr;
    }
    table_.erase(victim);
    ++stats_.evicted;
  }
  return &table_[id];
}

void BusTopologyTracker::on_message(const BusMessage& m, TimeNs receive_ns) {
  Entry* e = entry_for(m.creator_id, receive_ns);
  if (!e) return;
  ++stats_.messages;
  ++stats_.messages_by_type[static_cast<std::size_t>(m.type) & 3];
  e->last_seen_ns = std::max(e->last_seen_ns, receive_ns);
  // Only the base's own messages reach the host with the parent still empty.
  if (m.parent_id == kNoComponent) base_id_ = m.creator_id;
  // The parent filled this message in: it was alive then too. Without this a
  // splitter, which speaks only at 2 Hz, could fall silent for 2 s up to
  // 0.5 s before it really left, and take its subtree with it early.
  if (m.parent_id != kNoComponent) {
    if (auto p = table_.find(m.parent_id); p != table_.end()) {
      p->second.last_seen_ns = std::max(p->second.last_seen_ns, receive_ns);
    }
  }

  const bool newest = !e->any || bus_newer(m.boot, m.clock_us, e->boot, e->clock_us);
  if (!newest) {
    ++stats_.stale_messages;
  } else {
    if (e->any && m.boot != e->boot) ++e->reboots;
    e->any = true;
    e->boot = m.boot;
    e->clock_us = m.clock_us;
    if (e->parent_id != m.parent_id || e->parent_outlet != m.parent_outlet) {
      e->parent_id = m.parent_id;
      e->parent_outlet = m.parent_outlet;
      ++stats_.parent_changes;
    }
  }
  switch (m.type) {
    case BusMessageType::data:
      if (!e->have_angles || bus_newer(m.boot, m.clock_us, e->angles_boot, e->angles_clock_us)) {
        e->have_angles = true;
        e->angles = m.data;
        e->angles_ns = receive_ns;
        e->angles_boot = m.boot;
        e->angles_clock_us = m.clock_us;
      }
      break;
    case BusMessageType::type:
      if (newest || !e->type_known) {
        e->type_known = true;
        e->type = m.type_info;
      }
      break;
    case BusMessageType::child:
      if (newest && m.child.outlet < kMaxOutlets) {
        BusOutletView& o = e->outlets[m.child.outlet];
        o.known = true;
        o.child_id = m.child.child_id;
        o.q_inlet_outlet = rotation_from_wire(m.child.q_wxyz);
      }
      break;
  }
}

std::unordered_map<std::uint32_t, bool> BusTopologyTracker::attached_at(TimeNs now_ns) const {
  // 0 unknown, 1 in progress, 2 attached, 3 detached.
  std::unordered_map<std::uint32_t, std::uint8_t> state;
  state.reserve(table_.size());
  std::vector<std::uint32_t> chain;
  for (const auto& [id0, e0] : table_) {
    chain.clear();
    std::uint32_t id = id0;
    std::uint8_t verdict = 0;
    for (;;) {
      auto s = state.find(id);
      if (s != state.end()) {
        verdict = s->second == 1 ? 3 : s->second;  // a cycle detaches
        break;
      }
      const auto it = table_.find(id);
      if (it == table_.end()) {
        verdict = 3;
        break;
      }
      const Entry& e = it->second;
      const bool recent = e.any && now_ns - e.last_seen_ns < options_.detach_after_ns;
      if (!recent) {
        state[id] = 3;
        verdict = 3;
        break;
      }
      if (e.parent_id == kNoComponent) {
        verdict = id == base_id_ ? 2 : 3;
        state[id] = verdict;
        break;
      }
      state[id] = 1;
      chain.push_back(id);
      id = e.parent_id;
    }
    for (const std::uint32_t c : chain) state[c] = verdict;
  }
  std::unordered_map<std::uint32_t, bool> out;
  out.reserve(state.size());
  for (const auto& [id, e] : table_) out[id] = state[id] == 2;
  return out;
}

void BusTopologyTracker::update(TimeNs now_ns) {
  const auto attached = attached_at(now_ns);
  for (auto& [id, e] : table_) {
    const bool a = attached.at(id);
    if (a && !e.attached) ++stats_.attaches;
    if (!a && e.attached) ++stats_.detaches;
    e.attached = a;
  }
}

std::vector<BusTopologyTracker::Edge> BusTopologyTracker::attached_edges(TimeNs now_ns) const {
  const auto attached = attached_at(now_ns);
  std::vector<Edge> out;
  for (const auto& [id, e] : table_) {
    if (attached.at(id)) out.push_back({id, e.parent_id, e.parent_outlet});
  }
  std::sort(out.begin(), out.end());
  return out;
}

BusSnapshot BusTopologyTracker::snapshot(TimeNs now_ns) const {
  const auto attached = attached_at(now_ns);
  BusSnapshot s;
  s.time_ns = now_ns;
  s.base_id = base_id_;
  s.components.reserve(table_.size());
  for (const auto& [id, e] : table_) {
    BusComponentView v;
    v.id = id;
    v.type_known = e.type_known;
    if (e.type_known) {
      v.kind = e.type.kind;
      v.kind_name = kind_name_of(e.type);
      v.colour_rgb = e.type.colour_rgb;
      v.outlet_count = e.type.outlet_count;
    }
    v.parent_id = e.parent_id;
    v.parent_outlet = e.parent_outlet;
    v.attached = attached.at(id);
    v.boot = e.boot;
    v.reboots_seen = e.reboots;
    v.silent_ns = now_ns - e.last_seen_ns;
    v.have_angles = e.have_angles;
    if (e.have_angles) {
      v.angles = angles_from_wire(e.angles);
      v.angles_age_ns = now_ns - e.angles_ns;
    }
    if (e.type_known && e.type.kind != ComponentKind::joint) {
      v.outlets.assign(e.outlets.begin(), e.outlets.begin() + std::min<std::size_t>(e.type.outlet_count, kMaxOutlets));
    }
    if (v.attached) ++s.attached;
    s.components.push_back(std::move(v));
  }
  std::sort(s.components.begin(), s.components.end(),
            [](const BusComponentView& a, const BusComponentView& b) { return a.id < b.id; });
  return s;
}

BusDecodeStatus RigBusHost::on_report(std::span<const std::uint8_t> report, TimeNs receive_ns) {
  ++stats_.reports;
  const BusDecodeStatus s = decode_rig_bus_report(report, last_);
  if (!s) {
    ++stats_.decode_errors;
    ++stats_.decode_errors_by_code[static_cast<std::size_t>(s.code) % kBusDecodeErrcCount];
    return s;
  }
  for (std::size_t i = 0; i < last_.count; ++i) {
    tracker_.on_message(last_.messages[i], receive_ns);
    ++stats_.messages;
  }
  return s;
}

RigBusHostStats RigBusHost::stats() const {
  RigBusHostStats s = stats_;
  s.tracker = tracker_.stats();
  return s;
}

}  // namespace proprio::rig_bus
