#pragma once
/// The scene recording file (`.rcbscene`), versions 1 to 3. Version 2 stores shapes: each
/// object is u32 uid, u8 shape kind (shape.h), then f32 min[3], max[3] for a box (kind 0) or the
/// shape's floats, its box being the shape's bounds. Version 3 is version 2 plus a query kind per
/// ray (scene.h, QueryKind): each FRAM ends with rays × u8 kind (0 all, 1 closest, 2 any). The
/// writer uses the lowest version that holds the recording: 1 when every object is a box and every
/// ray asks for all hits, so a scene's bytes (and its hash in the results) do not change; every
/// version reads.
///
/// Every integer and float is little-endian whatever the host; floats are IEEE-754 binary32.
///
///     header   8 bytes  magic "RCBSCENE"
///              u32      format version (1 or 2)
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
///                          version 3: rays × u8 query kind
///     END   once, last, empty payload: a file without it was cut short.
///
/// The reader validates everything: magic, version, checksums, section order and sizes, finite
/// coordinates within ±kMaxCoordinate, min <= max, unique uids, and that removes and moves name
/// live uids and inserts new ones. Every error is an InputError naming the file, and the frame, uid or ray concerned.

#include <string>
#include <string_view>

#include "core/scene/scene.h"

namespace rcb {

/// The newest version this reader understands (it reads every older one too).
inline constexpr std::uint32_t kRecordingVersion = 3;
/// The version encode_recording writes: 3 when some ray is not `all`, else 2 when some object has
/// a shape, else 1.
std::uint32_t recording_version(const Recording& recording);

/// Refuses first (refuse_invalid_recording: a recording the reader would reject is never written;
/// the InputError names `path`), then writes atomically: to a temporary file beside `path`,
/// renamed over it when complete.
void write_recording(const Recording& recording, const std::string& path);
Recording read_recording(const std::string& path);

/// The encoded bytes (what write_recording writes); the same recording gives the same bytes.
std::string encode_recording(const Recording& recording);
/// Decodes and validates; `name` is used in error messages.
Recording decode_recording(const std::string& bytes, const std::string& name);

/// Checks a recording's contents (the same checks the reader makes); throws InputError naming
/// `name`, the frame and the uid or ray.
void refuse_invalid_recording(const Recording& recording, const std::string& name);
/// refuse_invalid_recording's old name, kept for one release; it goes with the next.
inline void validate_recording(const Recording& recording, const std::string& name) {
    refuse_invalid_recording(recording, name);
}

/// The largest |coordinate| of a box or a segment's end point that rcbench accepts, wherever a
/// scene or a ray enters (recordings read and written, CSV, BSP and model imports). Every structure
/// and peer must represent such scenes exactly, and the tightest is Embree: it asserts on a ray
/// whose |origin| or |direction| exceeds its FLT_LARGE (1.8e18) and silently drops a primitive
/// whose bounds do, and the Embree peer sends rays reaching up to 16 x the largest box coordinate
/// through it, with padded bounds. At 1e15, ray origins of 1.6e16 and directions of 3.2e16 stay
/// more than fifty times below FLT_LARGE, squared extents (surface areas, ~1e31) stay far inside
/// float's range, and every structure matches the ground truth on boxes and rays spread at that
/// magnitude and on a box 1e15 long among unit boxes (peers_test). Floats there are 2^26 apart:
/// such scenes are coarse, but exact.
inline constexpr double kMaxCoordinate = 1e15;
/// The smallest |coordinate| accepted other than zero. Float arithmetic stops being exact far
/// above float's smallest normal (1.2e-38): the slab test's reciprocal 1/d overflows for a
/// direction component below 2.9e-39 (brute force itself disagreed with the ground truth on
/// coordinates of 1e-42), and products of extents underflow (the dynamic BVH's binning crashed on
/// a scene 1e-29 across). At 1e-20 nonzero coordinates are far from all of these, and rounding
/// noise of real scenes (1e-16 and up) still passes; smaller values are to be written as 0.
inline constexpr double kMinCoordinate = 1e-20;

/// Empty when the coordinate is finite and zero or within [kMinCoordinate, kMaxCoordinate] in
/// magnitude, else what is wrong with it ("non-finite coordinate", "coordinate 1e+20 beyond ±1e+15
/// (...)", "coordinate 3e-25 below 1e-20 ..."). `text`, when given, is the value as the user wrote
/// it, shown (quoted) instead of the number: "1e400" overflows even double.
std::string coordinate_problem(double value, std::string_view text = {});
/// Empty when the box is valid (coordinate_problem finds nothing, min <= max on every axis), else
/// what is wrong with it.
std::string box_problem(const Aabb& box);
/// Empty when the segment's coordinates pass coordinate_problem, else what is wrong with it.
std::string segment_problem(const Segment& segment);
/// Throws InputError "<context>: uid N: <problem>" when box_problem finds a problem in o's box:
/// the one check every importer makes on the objects it produces.
void check_object(const Object& o, const std::string& context);

}  // namespace rcb
