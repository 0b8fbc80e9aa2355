#pragma once
// HidTransport: the narrow interface between a device driver and USB HID
// (in the spirit of Monado's os_hid_device and CHAI3D's device abstraction):
// open, read one report with a timeout, write one report, read a feature
// report, close. Reports are exchanged as hidapi does for devices with
// numbered reports: report ID first.
//
// Two implementations:
//   HidapiTransport  a real device through hidapi (hidraw on Linux), found by
//                    VID/PID/serial or path; a read error (the device was
//                    unplugged) closes it, and open() finds it again after
//                    replugging. The retry policy (backoff, state reports)
//                    lives in the driver, so it is the same for every transport.
//   FakeHidTransport an in-memory device for tests: a queue of reports with
//                    release times, and the faults a USB link shows (unplug
//                    for N ms, corrupted bytes, lost, duplicated and
//                    reordered reports).
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <condition_variable>
#include <span>
#include <string>
#include <vector>

#include "proprio/core/random.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/hid/usb_ids.hpp"

struct hid_device_;  // hidapi's handle; its header stays out of ours

namespace proprio::hid {

class HidTransport {
 public:
  virtual ~HidTransport() = default;

  // Opens the device (again, after an unplug). Errc::not_found when it is not
  // there, Errc::io_error when the OS refuses (permissions: see docs/glove-hid-protocol.md).
  virtual Status open() = 0;
  virtual void close() noexcept = 0;
  virtual bool is_open() const noexcept = 0;
  // Waits up to timeout for one input report and copies it into buffer
  // (truncated to the buffer). Returns its length, or 0 when the timeout
  // passed. Errc::unavailable when the device is gone; the transport is then
  // closed and open() may be tried again.
  virtual Result<std::size_t> read(std::span<std::uint8_t> buffer, DurationNs timeout) = 0;
  // Sends one output report (report ID first).
  virtual Status write(std::span<const std::uint8_t> report) = 0;
  // Reads feature report report_id into buffer (report ID first); returns its length.
  virtual Result<std::size_t> get_feature(std::uint8_t report_id, std::span<std::uint8_t> buffer) = 0;
  // For logs: which device, how it was found.
  virtual std::string describe() const = 0;
};

// A HID interface as the OS lists it.
struct HidDeviceInfo {
  std::string path;  // e.g. /dev/hidraw3
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  std::uint16_t release = 0;  // bcdDevice
  std::string serial;
  std::string manufacturer;
  std::string product;
  std::uint16_t usage_page = 0;
  std::uint16_t usage = 0;
  int interface_number = -1;
};

// Lists HID interfaces; vendor_id/product_id 0 match any. Errc::io_error if
// hidapi cannot initialise.
Result<std::vector<HidDeviceInfo>> enumerate_hid_devices(std::uint16_t vendor_id = 0, std::uint16_t product_id = 0);
std::string hidapi_version();

struct HidDeviceSelector {
  // The product ID is the device's (each protocol declares its own); 0: any.
  std::uint16_t vendor_id = kPidCodesVendorId;
  std::uint16_t product_id = 0;
  std::string serial;  // empty: any
  std::string path;    // non-empty: exactly this device node, other fields ignored
  // Only interfaces with this usage page (0: any). Interfaces whose usage page
  // the OS does not report (0) are accepted too.
  std::uint16_t usage_page = kVendorDefinedUsagePage;
  std::string describe() const;
};

// An explicit device path must name a hidraw character device: anything else
// (/dev/null, /dev/zero, a regular file) is refused before hidapi sees it.
Status check_hidraw_node(const std::string& path);

class HidapiTransport final : public HidTransport {
 public:
  explicit HidapiTransport(HidDeviceSelector selector = {});
  ~HidapiTransport() override;
  HidapiTransport(const HidapiTransport&) = delete;
  HidapiTransport& operator=(const HidapiTransport&) = delete;

  Status open() override;
  void close() noexcept override;
  bool is_open() const noexcept override { return device_ != nullptr; }
  Result<std::size_t> read(std::span<std::uint8_t> buffer, DurationNs timeout) override;
  Status write(std::span<const std::uint8_t> report) override;
  Result<std::size_t> get_feature(std::uint8_t report_id, std::span<std::uint8_t> buffer) override;
  std::string describe() const override;

 private:
  std::string last_error() const;
  HidDeviceSelector selector_;
  hid_device_* device_ = nullptr;
  HidDeviceInfo opened_;
};

// ---------------------------------------------------------------------------
// Fake transport.

struct FakeHidFaults {
  double drop_probability = 0.0;
  double duplicate_probability = 0.0;
  double corrupt_probability = 0.0;  // one random bit flipped
  double reorder_probability = 0.0;  // held back and delivered after the next report
  std::uint64_t seed = 1;
};

struct FakeHidLinkStats {
  std::uint64_t pushed = 0;
  std::uint64_t delivered = 0;
  std::uint64_t dropped = 0;
  std::uint64_t duplicated = 0;
  std::uint64_t corrupted = 0;
  std::uint64_t reordered = 0;
  std::uint64_t lost_unplugged = 0;  // due while the cable was out
  std::uint64_t opens = 0;
  std::uint64_t failed_opens = 0;
  std::uint64_t read_errors = 0;
  std::uint64_t writes = 0;
};

// The device end of a fake link plus the cable: tests push reports into it
// and script faults; FakeHidTransport is the host end. Shared between the test
// thread and the reader thread; every member is thread-safe.
class FakeHidLink {
 public:
  // clock: the time base of release times and unplug intervals (the same
  // clock the ImuGloveDevice stamps receive times with).
  explicit FakeHidLink(const Clock& clock = MonotonicClock::instance(), FakeHidFaults faults = {});

  // Queues a report the host can read from release_ns on. Faults apply here.
  void push(std::span<const std::uint8_t> report, TimeNs release_ns = 0);
  // The cable comes out at at_ns for duration_ns: an open handle dies (its
  // next read fails), open() fails until the end, and reports due meanwhile
  // are lost.
  void schedule_unplug(TimeNs at_ns, DurationNs duration_ns);
  void unplug_for(DurationNs duration_ns) { schedule_unplug(clock_.now_ns(), duration_ns); }
  // Releases a report still held back for reordering (the end of a test's stream).
  void flush();
  bool plugged() const;

  // What the device does with host traffic. Handlers run on the host's thread,
  // without the link's lock held (they may push).
  void set_write_handler(std::function<void(std::span<const std::uint8_t>)> handler);
  // Fills out (report ID first) and returns the length, or 0 for "no such report".
  void set_feature_handler(std::function<std::size_t(std::uint8_t, std::span<std::uint8_t>)> handler);

  std::vector<std::vector<std::uint8_t>> writes() const;
  std::size_t pending() const;
  FakeHidLinkStats stats() const;

 private:
  friend class FakeHidTransport;
  struct Entry {
    TimeNs release_ns = 0;
    std::vector<std::uint8_t> bytes;
  };
  struct Outage {
    TimeNs at_ns;
    TimeNs until_ns;
  };
  bool unplugged_at(TimeNs t) const;  // lock held
  // Whether an outage began after opened_ns and by now: the handle is dead. Lock held.
  bool outage_since(TimeNs opened_ns, TimeNs now) const;
  void enqueue(Entry entry);  // lock held

  const Clock& clock_;
  FakeHidFaults faults_;
  Rng drop_rng_, duplicate_rng_, corrupt_rng_, reorder_rng_;
  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<Entry> queue_;
  std::vector<Entry> held_;  // at most one, held back for reordering
  std::vector<Outage> outages_;
  std::vector<std::vector<std::uint8_t>> writes_;
  std::function<void(std::span<const std::uint8_t>)> write_handler_;
  std::function<std::size_t(std::uint8_t, std::span<std::uint8_t>)> feature_handler_;
  FakeHidLinkStats stats_;
};

class FakeHidTransport final : public HidTransport {
 public:
  explicit FakeHidTransport(std::shared_ptr<FakeHidLink> link);

  Status open() override;
  void close() noexcept override;
  bool is_open() const noexcept override { return open_; }
  Result<std::size_t> read(std::span<std::uint8_t> buffer, DurationNs timeout) override;
  Status write(std::span<const std::uint8_t> report) override;
  Result<std::size_t> get_feature(std::uint8_t report_id, std::span<std::uint8_t> buffer) override;
  std::string describe() const override { return "fake HID link"; }

 private:
  Status check_alive();  // closes and errs if the cable came out since open()
  std::shared_ptr<FakeHidLink> link_;
  bool open_ = false;
  TimeNs opened_ns_ = 0;
};

}  // namespace proprio::hid
