#pragma once
/// Broadmark's scene files (Serpa & Rodrigues 2019, "Broadmark: a testing framework for
/// broad-phase collision detection algorithms"; its generator writes them as `*.aabbs`): a fixed
/// set of N boxes per frame, no rays, no shapes. docs/recording-format.md ("Broadmark scene files")
/// gives the layout: a 304-byte header (scene name and object type as 128-byte NUL-terminated
/// strings, i32 N, i32 frames, two zero i32, the world box), then per frame N boxes of 8 float32
/// (min x y z 0, max x y z 0), all little-endian.
///
/// Import: the first frame is frame 0 (uid = index), each later frame moves the objects whose box
/// changed (bit for bit). Export writes every object in every frame. The header's fields are kept
/// in the recording's meta ("broadmark"), so export(import(file)) gives the file back byte for
/// byte when its strings are zero-padded after their NUL (as Broadmark's generator writes them).

#include <string>

#include "core/scene/scene.h"

namespace rcb {

inline constexpr std::size_t kBroadmarkHeaderBytes = 304;

/// The recording in a Broadmark file: objects and moves, no rays. InputError naming the file and
/// the header field, frame or object for anything malformed.
Recording read_broadmark(const std::string& path);
Recording decode_broadmark(const std::string& bytes, const std::string& name);

/// The Broadmark bytes of a recording's boxes (shapes are written as their boxes). InputError
/// naming `name` and the frame when a frame inserts or removes objects (Broadmark's N is fixed)
/// or the recording has no objects.
std::string encode_broadmark(const Recording& recording, const std::string& name);
/// encode_broadmark, written atomically to `path`.
void write_broadmark(const Recording& recording, const std::string& path);

}  // namespace rcb
