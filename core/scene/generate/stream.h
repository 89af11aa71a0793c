#pragma once
/// The generators streamed: each frame given to a SceneSink (core/scene/recording_stream.h) as it is
/// made, so that `scene gen` writes a recording of any length in the memory of one frame.

#include <cstdint>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/scene/generate/generators.h"
#include "core/scene/recording_stream.h"

namespace rcb {

/// The same scene given to `sink` frame by frame as it is made, so that
/// `scene gen` holds one frame, not the recording: the frames are bounded only by the file
/// (check_streamed_scene_size). Same settings, same frames as generate_scene.
void stream_scene(const SceneSettings& settings, SceneSink& sink);
/// add_dynamics streamed into `sink`, one frame at a time (stream_scene).
void stream_dynamics(std::vector<Object> initial, const DynamicsSettings& dynamics, const RaySettings& rays,
                     std::uint32_t frames, std::uint64_t seed, nlohmann::json meta, SceneSink& sink);

}  // namespace rcb
