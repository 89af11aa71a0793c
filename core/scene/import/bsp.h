#pragma once
/// Quake III Arena / OpenArena maps: IBSP version 46 (the format of id Tech 3; lumps as documented
/// in Kekoa Proudfoot's "Unofficial Quake 3 Map Specs" and id's qfiles.h).
///
/// Modes:
///  - `brushes`: one object per solid brush, the game's collision world. A brush's AABB comes from
///    its axial sides (brushsides whose plane normal is ±x, ±y or ±z; q3map2 always emits the six
///    axial planes of a brush, bevels included, so every well-formed brush has them). A brush counts
///    as solid when its shader's contents include CONTENTS_SOLID (0x1) or CONTENTS_PLAYERCLIP
///    (0x10000): the brushes a player collides with (MASK_PLAYERSOLID without CONTENTS_BODY, which
///    marks entities, not brushes). Water, lava, slime, fog, triggers, areaportals and hint/detail-only
///    non-solid brushes are skipped. Brushes of every model are taken (world and brush entities such
///    as doors, at their rest positions). A brush missing an axial side on some axis is skipped.
///  - `triangles`: one object per triangle of the draw surfaces: planar faces and triangle meshes
///    (types 1 and 3) through their meshverts; Bézier patches (type 2) as the two triangles per
///    cell of their control-point grid (an approximation of the curved surface: the patch lies in
///    the convex hull of its control points, so together the triangles' boxes are close to, not
///    exactly, the surface's); billboards (type 4) are skipped.
///
/// Before allocating objects, the importer counts them (triangles mode: exactly, from the surfaces'
/// index counts and patch sizes) and refuses more than kMaxSceneObjects (scene.h); every object's
/// box is checked against the coordinate limit (check_object, recording_io.h). Surfaces may share
/// vertices and indexes, so a small file can expand to millions of triangles: triangles mode also
/// refuses more than a budget (BspOptions::max_triangles, kDefaultBspMaxTriangles), a bound on
/// the import's time and memory that a real map stays far below, raised on request.
///
/// Every lump must lie inside the file, whether the mode reads it or not: a truncated map is
/// refused, naming the first lump cut off, in both modes.
///
/// A `.pk3` is a zip: the map is read from `maps/NAME.bsp` inside it (libzip). Errors name the file
/// and the lump: "q3dm1.bsp: lump 8 (brushes): length 13 is not a multiple of 12".

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/scene/scene.h"

namespace rcb {

/// The largest map read (a .bsp file, or a map's uncompressed size inside a .pk3), checked before
/// its bytes are allocated: OpenArena's and Quake III's largest maps are under 20 MB, so 512 MiB
/// only stops a corrupt or hostile size (a zip entry claiming gigabytes).
inline constexpr std::uint64_t kMaxMapBytes = std::uint64_t(512) << 20;

/// The default budget of triangles mode. Every triangle of a real map needs its own indexes or
/// patch control points in the file (12 or about 22 bytes each), so the largest maps (under 20 MB)
/// stay under two million; four Mi triangles are reached only by surfaces that share their data.
inline constexpr std::uint64_t kDefaultBspMaxTriangles = std::uint64_t(1) << 22;

struct BspOptions {
    std::string mode = "brushes";  ///< "brushes" or "triangles"
    std::string map;               ///< in a .pk3 with several maps: which (NAME or maps/NAME.bsp)
    std::uint64_t max_triangles = kDefaultBspMaxTriangles;  ///< triangles mode's budget
};

/// What an import kept and skipped (for messages and the recording's meta).
struct BspSummary {
    std::size_t brushes = 0, solid_brushes = 0, skipped_non_solid = 0, skipped_not_closed = 0;
    std::size_t surfaces = 0, triangles = 0;
    std::string map;  ///< the map actually read (for a pk3: the entry name)
};

/// Reads a .bsp file or a map inside a .pk3. Throws InputError naming the file (and entry, lump).
std::vector<Object> import_bsp(const std::string& path, const BspOptions& options, BspSummary* summary = nullptr);

/// The same from bytes in memory; `name` is used in messages.
std::vector<Object> parse_bsp(std::span<const std::uint8_t> bytes, const std::string& name, const std::string& mode,
                              BspSummary* summary = nullptr, std::uint64_t max_triangles = kDefaultBspMaxTriangles);

/// Metres per map unit when a map is placed in a physics scene (a unit taken as an inch: a player
/// stands 56 units, 1.4 m, tall).
inline constexpr double kBspUnitMetres = 0.0254;

/// A map's box (z up, map units) in the physics scenes' frame (metres, y up): the map's x stays x,
/// its z becomes y and its y becomes −z, a quarter turn about x that keeps handedness.
Aabb bsp_box_in_metres(const Aabb& box);

/// The maps (`maps/*.bsp` entries) inside a .pk3, sorted.
std::vector<std::string> pk3_maps(const std::string& path);

/// One entry of a zip file, whole. Throws InputError naming the file and entry.
std::vector<std::uint8_t> read_zip_entry(const std::string& path, const std::string& entry);

}  // namespace rcb
