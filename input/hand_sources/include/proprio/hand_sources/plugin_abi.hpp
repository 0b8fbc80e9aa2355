#pragma once
// The contract between the hand-source factory and a plugin
// (libproprio_source_<family>.so): a hand-source family (vist, stretch_glove,
// ftm), or the fingertip devices behind the OpenXR layer's haptics (family
// "haptics", whose table has start_haptics and whose start refuses). A plugin exports exactly one symbol,
// `proprio_hand_source_plugin_v1`, returning a table the host checks before
// using anything else in it:
//   - struct_size and abi_version first (their offsets never change), so a
//     plugin from another release is refused before its other fields are read;
//   - build_id: the plugin passes C++ types (SourceConfig, HandSource, Result)
//     across the boundary, which is sound only between a host and a plugin
//     built from the same sources with the same compiler. The id hashes the
//     headers those types come from, the compiler and the project version
//     (input/hand_sources/CMakeLists.txt), so a stale plugin is refused, not run.
//   - No exception crosses the boundary: every function in the table is
//     noexcept and maps exceptions to an Error (plugin_guarded below).
#include <cstdint>
#include <exception>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "proprio/core/hand_source.hpp"
#include "proprio/core/log.hpp"
#include "proprio/core/result.hpp"
#include "proprio/core/time.hpp"
#include "proprio/core/tracked_pose_provider.hpp"
#include "proprio/openxr_layer/fingertip_haptics_service.hpp"
#include "proprio/openxr_layer/layer_config.hpp"

namespace proprio::hand_sources {

// Bump when the table's layout or meaning changes.
inline constexpr std::uint32_t kPluginAbiVersion = 3;
inline constexpr const char* kPluginEntryPoint = "proprio_hand_source_plugin_v1";

// What a plugin's start returns.
struct PluginStarted {
  std::unique_ptr<HandSource> source;
  // The files the plugin read through proprio::core's file_io (see hand_sources.cpp,
  // "duplicated static state"): the host remembers them as its own inputs.
  std::vector<std::filesystem::path> inputs;
};

struct HandSourcePluginV1 {
  std::uint32_t struct_size = sizeof(HandSourcePluginV1);
  std::uint32_t abi_version = kPluginAbiVersion;
  const char* build_id = nullptr;
  const char* family = nullptr;  // "vist", "stretch_glove"
  // Starts the source `config` describes (a type this family serves).
  // `poses` (may be null; outlives the source): what the host tracks, e.g. the
  // head for a head-mounted camera.
  Result<PluginStarted> (*start)(const openxr_layer::SourceConfig& config, DurationNs max_prediction_ns,
                                 TrackedPoseProvider* poses) noexcept = nullptr;
  // The address of the spdlog logger the plugin's copy of proprio::logger()
  // writes to: the host checks it is its own (one logger per process).
  const void* (*logger_address)() noexcept = nullptr;
  // The "haptics" family only (null in the others): starts the devices a
  // [haptics] table configures, zeroed and stopped when the service is destroyed.
  Result<std::unique_ptr<openxr_layer::FingertipHapticsService>> (*start_haptics)(
      const openxr_layer::HapticsConfig& config) noexcept = nullptr;
};

using PluginEntryPointV1 = const HandSourcePluginV1* (*)() noexcept;

// Runs body, turning any exception into an Error: what a plugin's table
// functions wrap themselves in (the layer's guarded() for Result).
template <typename T, typename F>
Result<T> plugin_guarded(const char* what, F&& body) noexcept {
  try {
    return body();
  } catch (const std::exception& e) {
    try { return make_error(Errc::unavailable, std::string(what) + ": internal error: " + e.what()); } catch (...) {}
  } catch (...) {
    try { return make_error(Errc::unavailable, std::string(what) + ": unknown internal error"); } catch (...) {}
  }
  // Out of memory while building the message: an Error with no message.
  return Error{Errc::unavailable, {}};
}

// In a plugin: the address of its copy of proprio::logger()'s logger.
inline const void* plugin_logger_address() noexcept { return &logger(); }

}  // namespace proprio::hand_sources

// Defines a plugin's entry point: its table, with `start_fn`
// (Result<PluginStarted>(const SourceConfig&, DurationNs, TrackedPoseProvider*),
// which may throw)
// behind plugin_guarded. One use per plugin, at global scope.
#define PROPRIO_DEFINE_HAND_SOURCE_PLUGIN(family_name, start_fn)                                                     \
  extern "C" __attribute__((visibility("default"))) const ::proprio::hand_sources::HandSourcePluginV1*              \
  proprio_hand_source_plugin_v1() noexcept {                                                                         \
    static const ::proprio::hand_sources::HandSourcePluginV1 table{                                                  \
        sizeof(::proprio::hand_sources::HandSourcePluginV1), ::proprio::hand_sources::kPluginAbiVersion,            \
        PROPRIO_HAND_SOURCE_BUILD_ID, family_name,                                                                   \
        [](const ::proprio::openxr_layer::SourceConfig& config, ::proprio::DurationNs max_prediction_ns,            \
           ::proprio::TrackedPoseProvider* poses) noexcept {                                                         \
          return ::proprio::hand_sources::plugin_guarded<::proprio::hand_sources::PluginStarted>(                   \
              family_name " plugin", [&] { return start_fn(config, max_prediction_ns, poses); });                   \
        },                                                                                                           \
        &::proprio::hand_sources::plugin_logger_address};                                                            \
    return &table;                                                                                                   \
  }

// The "haptics" plugin's entry point: `start_fn`
// (Result<std::unique_ptr<FingertipHapticsService>>(const HapticsConfig&), which may throw).
#define PROPRIO_DEFINE_HAPTICS_PLUGIN(start_fn)                                                                      \
  extern "C" __attribute__((visibility("default"))) const ::proprio::hand_sources::HandSourcePluginV1*              \
  proprio_hand_source_plugin_v1() noexcept {                                                                         \
    static const ::proprio::hand_sources::HandSourcePluginV1 table{                                                  \
        sizeof(::proprio::hand_sources::HandSourcePluginV1), ::proprio::hand_sources::kPluginAbiVersion,            \
        PROPRIO_HAND_SOURCE_BUILD_ID, "haptics",                                                                     \
        [](const ::proprio::openxr_layer::SourceConfig&, ::proprio::DurationNs,                                     \
           ::proprio::TrackedPoseProvider*) noexcept -> ::proprio::Result<::proprio::hand_sources::PluginStarted> { \
          return ::proprio::make_error(::proprio::Errc::unsupported, "the haptics plugin serves no hand source");   \
        },                                                                                                           \
        &::proprio::hand_sources::plugin_logger_address,                                                             \
        [](const ::proprio::openxr_layer::HapticsConfig& config) noexcept {                                          \
          return ::proprio::hand_sources::plugin_guarded<                                                            \
              std::unique_ptr<::proprio::openxr_layer::FingertipHapticsService>>("haptics plugin",                  \
                                                                                 [&] { return start_fn(config); }); \
        }};                                                                                                          \
    return &table;                                                                                                   \
  }
