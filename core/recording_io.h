#pragma once
/// The scene recording file (`.rcbscene`), version 1.
///
/// Every integer and float is little-endian whatever the host; floats are IEEE-754 binary32.
///
///     header   8 bytes  magic "RCBSCENE"
///              u32      format version (1)
///              u32      byte-order mark 0x01020304, as written by the little-endian encoder;
///                       a reader seeing 0x04030201 knows the file was byte-swapped
///     sections, each:
///              4 bytes  tag: "META", "OBJS", "FRAM" or "END "
///              u64      payload length in bytes
///              u32      CRC-32 (zlib) of the payload
///              payload
///
///     META  once, first:   UTF-8 JSON text describing the scene's origin (generator, seed, source)
///     OBJS  once, second:  u32 n, then n objects       object = u32 uid, f32 min[3], f32 max[3]
///     FRAM  once per frame, in order:
///                          u32 frame number (1, 2, …; frame 0 is OBJS)
///                          u32 removes, u32 inserts, u32 moves, u32 rays
///                          removes × u32 uid, inserts × object, moves × object (uid, new box),
///                          rays × f32 p0[3], f32 p1[3]
///     END   once, last, empty payload: a file without it was cut short.
///
/// The reader validates everything: magic, version, checksums, section order and sizes, finite
/// coordinates, min <= max, unique uids, and that removes and moves name live uids and inserts
/// new ones. Every error is an InputError naming the file, and the frame, uid or ray concerned.

#include <string>

#include "core/scene.h"

namespace rcb {

inline constexpr std::uint32_t kRecordingVersion = 1;

/// Writes atomically: to a temporary file beside `path`, renamed over it when complete.
void write_recording(const Recording& recording, const std::string& path);
Recording read_recording(const std::string& path);

/// The encoded bytes (what write_recording writes); the same recording gives the same bytes.
std::string encode_recording(const Recording& recording);
/// Decodes and validates; `name` is used in error messages.
Recording decode_recording(const std::string& bytes, const std::string& name);

/// Checks a recording's contents (the same checks the reader makes); throws InputError naming
/// `name`, the frame and the uid or ray.
void validate_recording(const Recording& recording, const std::string& name);

/// Empty when the box is valid (finite, min <= max on every axis), else what is wrong with it.
std::string box_problem(const Aabb& box);
/// Empty when the segment's coordinates are finite, else what is wrong with it.
std::string segment_problem(const Segment& segment);

}  // namespace rcb
