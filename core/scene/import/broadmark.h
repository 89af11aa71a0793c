#pragma once
/// Broadmark's scene files (Serpa & Rodrigues 2019, "Broadmark: a testing framework for
/// broad-phase collision detection algorithms"; its generator writes them as `*.aabbs`): a fixed
/// set of N boxes per frame, no rays, no shapes. docs/recording-format.md ("Broadmark scene files")
/// gives the layout: a 304-byte header (scene name and object type as 128-byte NUL-terminated
/// strings, i32 N, i32 frames, two zero i32, the world box), then 1 + frames blocks of N boxes of
/// 8 float32 (min x y z 0, max x y z 0), all little-endian. Broadmark's reader (Core/Scene.h,
/// Scene::Scene and ValidateHeader) aborts unless the file is exactly 304 + 32·N·(1 + frames)
/// bytes with N > 0 and frames > 0: its generator (AABBsRecorder.cs, OnStart and OnStep) writes
/// the initial boxes, then one block per simulated frame, and frames counts the latter.
///
/// Import: the first block is frame 0 (uid = index), each later block one frame moving the objects
/// whose box changed (bit for bit). Export writes every object in every frame, frames = blocks − 1.
/// The header's strings and world box are kept in the recording's meta ("broadmark"), so
/// export(import(file)) gives a file Broadmark accepts back byte for byte.

#include <optional>
#include <string>

#include "core/scene/scene.h"

namespace rcb {

inline constexpr std::size_t kBroadmarkHeaderBytes = 304;

/// What to take of a Broadmark file: the first `frames` frames after frame 0 (unset: all) and the
/// first `objects` objects (0: all), and the rays the import will add per frame (for the memory
/// budget).
struct BroadmarkLimits {
    std::optional<std::uint32_t> frames;
    std::uint32_t objects = 0;
    std::uint32_t rays_per_frame = 0;
};

/// The recording in a Broadmark file: objects and moves, no rays. InputError naming the file and
/// the header field, frame or object for anything malformed or anything Broadmark's reader
/// refuses; naming the memory budget (kMaxRecordingBytes) and the --frames or --objects that stay
/// under it when the part taken would exceed it. Only the part taken is read.
Recording read_broadmark(const std::string& path, const BroadmarkLimits& limits = {});
Recording decode_broadmark(const std::string& bytes, const std::string& name, const BroadmarkLimits& limits = {});

/// The Broadmark bytes of a recording's boxes (shapes are written as their boxes), with frames =
/// the recording's frames after frame 0. InputError naming `name` (and the frame) when a frame
/// inserts or removes objects (Broadmark's N is fixed), the recording has no objects, or it has
/// only frame 0 (Broadmark's reader needs frames > 0).
std::string encode_broadmark(const Recording& recording, const std::string& name);
/// encode_broadmark, written atomically to `path`.
void write_broadmark(const Recording& recording, const std::string& path);

}  // namespace rcb
