// Broken hand-source plugins for test_hand_source_plugins.cpp, one MODULE per
// way of being wrong (FAKE_PLUGIN_*, tests/CMakeLists.txt).
#include "proprio/hand_sources/plugin_abi.hpp"

#ifndef FAKE_PLUGIN_NO_ENTRY_POINT
namespace {

proprio::Result<proprio::hand_sources::PluginStarted> start(const proprio::openxr_layer::SourceConfig&,
                                                            proprio::DurationNs,
                                                            proprio::TrackedPoseProvider*) noexcept {
  return proprio::make_error(proprio::Errc::unavailable, "fake plugin");
}
const void* logger_address() noexcept { return nullptr; }

}  // namespace

extern "C" __attribute__((visibility("default"))) const proprio::hand_sources::HandSourcePluginV1*
proprio_hand_source_plugin_v1() noexcept {
  static const proprio::hand_sources::HandSourcePluginV1 table{sizeof(proprio::hand_sources::HandSourcePluginV1),
                                                               FAKE_PLUGIN_ABI_VERSION, FAKE_PLUGIN_BUILD_ID,
                                                               "fake", &start, &logger_address};
  return &table;
}
#else
// A shared object with no entry point.
int fake_plugin_nothing_here = 0;
#endif
