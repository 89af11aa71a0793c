#pragma once
/// The scenes of one experiment entry that measure different windows of one recording (its phases,
/// runner/experiment.h "measure", core/scene/phases.h) replay the same frames: generators and
/// importers are deterministic per seed, so the runner generates (imports, reads) the recording
/// once per run and gives each window its own META, where each phase would otherwise generate the
/// whole physics simulation again.

#include <string>

#include "core/scene/scene.h"
#include "runner/experiment.h"

namespace rcb {

/// What identifies a scene's recording: its key without the window it measures ("measure"), and
/// its file. The windows of one entry share it.
std::string recording_key(const SceneSpec& scene);

/// The scene's recording as generated, imported or read, every frame, no window marked: the same
/// bytes for every scene of one recording_key.
Recording load_scene_frames(const SceneSpec& scene);

/// `recording`'s META with the frames `scene` measures marked as "measure" (core/scene/phases.h):
/// a phase's frames, or from a start frame to the end, every stride-th; the META unchanged for a
/// scene without a window. InputError naming the scene when the recording has no such frames.
std::string measured_meta(const SceneSpec& scene, const Recording& recording);

}  // namespace rcb
