// HidapiTransport: a real device through hidapi (hidraw backend on Linux).
#include "proprio/hid/hid_transport.hpp"

#include <hidapi.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>

#include <algorithm>
#include <climits>
#include <cstdio>
#include <filesystem>
#include <mutex>

#include "proprio/core/file_io.hpp"

namespace proprio::hid {

namespace {

// hidapi's strings are wchar_t (UTF-32 on Linux); everything else here is UTF-8.
std::string to_utf8(const wchar_t* w) {
  std::string out;
  if (!w) return out;
  for (; *w; ++w) {
    const auto c = static_cast<std::uint32_t>(*w);
    if (c < 0x80) {
      out += static_cast<char>(c);
    } else if (c < 0x800) {
      out += static_cast<char>(0xC0 | c >> 6);
      out += static_cast<char>(0x80 | (c & 0x3F));
    } else if (c < 0x10000) {
      out += static_cast<char>(0xE0 | c >> 12);
      out += static_cast<char>(0x80 | (c >> 6 & 0x3F));
      out += static_cast<char>(0x80 | (c & 0x3F));
    } else if (c < 0x110000) {
      out += static_cast<char>(0xF0 | c >> 18);
      out += static_cast<char>(0x80 | (c >> 12 & 0x3F));
      out += static_cast<char>(0x80 | (c >> 6 & 0x3F));
      out += static_cast<char>(0x80 | (c & 0x3F));
    }
  }
  return out;
}

// hid_init is not thread-safe and every other call initialises implicitly on
// first use; do it once, explicitly, so two threads cannot race into it.
Status init_hidapi() {
  static std::once_flag once;
  static int result = 0;
  std::call_once(once, [] { result = hid_init(); });
  if (result != 0) {
    return make_error(Errc::io_error, "hidapi could not initialise (hid_init returned " + std::to_string(result) +
                                          "): " + to_utf8(hid_error(nullptr)));
  }
  return {};
}

HidDeviceInfo to_info(const hid_device_info& d) {
  HidDeviceInfo i;
  i.path = d.path ? d.path : "";
  i.vendor_id = d.vendor_id;
  i.product_id = d.product_id;
  i.release = d.release_number;
  i.serial = to_utf8(d.serial_number);
  i.manufacturer = to_utf8(d.manufacturer_string);
  i.product = to_utf8(d.product_string);
  i.usage_page = d.usage_page;
  i.usage = d.usage;
  i.interface_number = d.interface_number;
  return i;
}

std::string hex4(std::uint16_t v) {
  char buf[8];
  std::snprintf(buf, sizeof buf, "%04x", v);
  return buf;
}

}  // namespace

Result<std::vector<HidDeviceInfo>> enumerate_hid_devices(std::uint16_t vendor_id, std::uint16_t product_id) {
  if (auto s = init_hidapi(); !s) return s.error();
  std::vector<HidDeviceInfo> out;
  hid_device_info* list = hid_enumerate(vendor_id, product_id);
  for (const hid_device_info* d = list; d; d = d->next) out.push_back(to_info(*d));
  hid_free_enumeration(list);
  std::sort(out.begin(), out.end(), [](const HidDeviceInfo& a, const HidDeviceInfo& b) { return a.path < b.path; });
  return out;
}

std::string hidapi_version() { return hid_version_str(); }

std::string HidDeviceSelector::describe() const {
  if (!path.empty()) return "HID device " + path;
  std::string s = "HID device " + hex4(vendor_id) + ":" + hex4(product_id);
  if (!serial.empty()) s += " with serial " + serial;
  return s;
}

Status check_hidraw_node(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    return make_error(Errc::not_found, "'" + printable(path) + "' does not exist: is the device plugged in? " +
                                           "'proprio glove list --all' shows the HID devices there are");
  }
  std::string why;
  if (!S_ISCHR(st.st_mode)) {
    why = S_ISDIR(st.st_mode) ? "a directory" : S_ISREG(st.st_mode) ? "a regular file" : "not a device node";
  } else {
    // hidapi's hidraw backend issues hidraw ioctls on whatever it opens, and
    // some other character devices make it crash: only hidraw nodes get through.
    const std::string link = "/sys/dev/char/" + std::to_string(major(st.st_rdev)) + ":" +
                             std::to_string(minor(st.st_rdev)) + "/subsystem";
    std::error_code ec;
    const auto subsystem = std::filesystem::read_symlink(link, ec);
    if (ec || subsystem.filename() != "hidraw") why = "a character device that is not a hidraw node";
  }
  if (!why.empty()) {
    return make_error(Errc::invalid_argument, "'" + printable(path) + "' is " + why +
                                                  "; pass a /dev/hidrawN node ('proprio glove list --all' lists them)");
  }
  return Status::success();
}

HidapiTransport::HidapiTransport(HidDeviceSelector selector) : selector_(std::move(selector)) {}

HidapiTransport::~HidapiTransport() { close(); }

std::string HidapiTransport::last_error() const {
  const std::string e = to_utf8(hid_error(device_));
  return e.empty() ? "no detail from hidapi" : e;
}

Status HidapiTransport::open() {
  if (device_) return {};
  if (auto s = init_hidapi(); !s) return s;

  HidDeviceInfo chosen;
  if (!selector_.path.empty()) {
    if (auto s = check_hidraw_node(selector_.path); !s) return s;
    chosen.path = selector_.path;
    // Fill in what the OS knows about that node, for describe(); opening does not depend on it.
    if (auto all = enumerate_hid_devices(); all) {
      for (const HidDeviceInfo& d : *all) {
        if (d.path == selector_.path) chosen = d;
      }
    }
  } else {
    auto list = enumerate_hid_devices(selector_.vendor_id, selector_.product_id);
    if (!list) return list.error();
    bool found = false;
    for (const HidDeviceInfo& d : *list) {
      if (!selector_.serial.empty() && d.serial != selector_.serial) continue;
      if (selector_.usage_page != 0 && d.usage_page != 0 && d.usage_page != selector_.usage_page) continue;
      chosen = d;
      found = true;
      break;
    }
    if (!found) {
      return make_error(Errc::not_found, "no " + selector_.describe() +
                                             " found: is the glove plugged in? 'proprio glove list --all' shows "
                                             "the HID devices there are");
    }
  }
  hid_device* dev = hid_open_path(chosen.path.c_str());
  if (!dev) {
    return make_error(Errc::io_error,
                      "cannot open " + chosen.path + " (" + selector_.describe() + "): " + to_utf8(hid_error(nullptr)) +
                          ". If it is a permission error, install the udev rule in docs/glove-hid-protocol.md "
                          "and replug the glove");
  }
  device_ = dev;
  opened_ = chosen;
  return {};
}

void HidapiTransport::close() noexcept {
  if (device_) hid_close(device_);
  device_ = nullptr;
}

Result<std::size_t> HidapiTransport::read(std::span<std::uint8_t> buffer, DurationNs timeout) {
  if (!device_) return make_error(Errc::unavailable, describe() + " is not open");
  // Round up so that a short timeout still waits, and keep within int.
  const DurationNs ms = std::clamp<DurationNs>((timeout + kNsPerMillisecond - 1) / kNsPerMillisecond, 0, INT_MAX);
  const int n = hid_read_timeout(device_, buffer.data(), buffer.size(), static_cast<int>(ms));
  if (n < 0) {
    const std::string why = last_error();
    close();
    return make_error(Errc::unavailable, "reading " + opened_.path + " failed (" + why +
                                             "): the glove was unplugged or reset");
  }
  return static_cast<std::size_t>(n);
}

Status HidapiTransport::write(std::span<const std::uint8_t> report) {
  if (!device_) return make_error(Errc::unavailable, describe() + " is not open");
  if (hid_write(device_, report.data(), report.size()) < 0) {
    return make_error(Errc::io_error, "writing a " + std::to_string(report.size()) + "-byte report to " +
                                          opened_.path + " failed: " + last_error());
  }
  return {};
}

Result<std::size_t> HidapiTransport::get_feature(std::uint8_t report_id, std::span<std::uint8_t> buffer) {
  if (!device_) return make_error(Errc::unavailable, describe() + " is not open");
  if (buffer.empty()) return make_error(Errc::invalid_argument, "get_feature needs a buffer of at least 1 byte");
  buffer[0] = report_id;
  const int n = hid_get_feature_report(device_, buffer.data(), buffer.size());
  if (n < 0) {
    char id[8];
    std::snprintf(id, sizeof id, "0x%02x", report_id);
    return make_error(Errc::io_error, std::string("reading feature report ") + id + " from " + opened_.path +
                                          " failed: " + last_error());
  }
  return static_cast<std::size_t>(n);
}

std::string HidapiTransport::describe() const {
  if (!device_) return "hidapi " + selector_.describe();
  std::string s = "hidapi " + hex4(opened_.vendor_id) + ":" + hex4(opened_.product_id);
  if (!opened_.serial.empty()) s += " serial " + opened_.serial;
  if (!opened_.product.empty()) s += " (" + opened_.product + ")";
  return s + " at " + opened_.path;
}

}  // namespace proprio::hid
