#include "core/scene/import/bsp.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include <zip.h>

#include "core/base/error.h"
#include "core/scene/recording_io.h"

namespace rcb {
namespace {

constexpr int kVersion = 46;
constexpr int kLumps = 17;
constexpr std::size_t kHeaderBytes = 8 + kLumps * 8;

// Lump indices and names as in id's qfiles.h.
enum Lump {
    kEntities,
    kShaders,
    kPlanes,
    kNodes,
    kLeafs,
    kLeafSurfaces,
    kLeafBrushes,
    kModels,
    kBrushes,
    kBrushSides,
    kDrawVerts,
    kDrawIndexes,
    kFogs,
    kSurfaces,
    kLightmaps,
    kLightGrid,
    kVisibility
};
constexpr std::array<const char*, kLumps> kLumpNames = {
    "entities",    "shaders",  "planes",    "nodes",      "leafs",     "leafsurfaces",
    "leafbrushes", "models",   "brushes",   "brushsides", "drawverts", "drawindexes",
    "fogs",        "surfaces", "lightmaps", "lightgrid",  "visibility"};

// Record sizes (bytes) of the lumps we read.
constexpr std::size_t kShaderBytes = 72;    // char name[64]; int surfaceFlags; int contentFlags
constexpr std::size_t kPlaneBytes = 16;     // float normal[3]; float dist
constexpr std::size_t kBrushBytes = 12;     // int firstSide; int numSides; int shaderNum
constexpr std::size_t kBrushSideBytes = 8;  // int planeNum; int shaderNum
constexpr std::size_t kDrawVertBytes =
    44;                                 // float xyz[3]; float st[2]; float lightmap[2]; float normal[3]; byte color[4]
constexpr std::size_t kIndexBytes = 4;  // int
constexpr std::size_t kSurfaceBytes = 104;  // see parse_triangles

// Contents flags (q3 surfaceflags.h) that make a brush part of the collision world.
constexpr std::int32_t kContentsSolid = 0x1;
constexpr std::int32_t kContentsPlayerClip = 0x10000;

// Surface types (q3 qfiles.h mapSurfaceType_t).
constexpr int kPlanar = 1, kPatch = 2, kTriangleSoup = 3;

struct Reader {
    std::span<const std::uint8_t> bytes;
    std::string name;
    std::array<std::uint32_t, kLumps> offset{}, length{};

    [[noreturn]] void fail_lump(int lump, const std::string& what) const {
        throw InputError(name + ": lump " + std::to_string(lump) + " (" + kLumpNames[lump] + "): " + what);
    }

    std::int32_t i32(std::size_t at) const {
        std::int32_t v;
        std::memcpy(&v, bytes.data() + at, 4);
        return v;
    }
    float f32(std::size_t at) const {
        float v;
        std::memcpy(&v, bytes.data() + at, 4);
        return v;
    }

    void header() {
        if (bytes.size() < kHeaderBytes)
            throw InputError(name + ": header: truncated (" + std::to_string(bytes.size()) + " bytes, a header needs " +
                             std::to_string(kHeaderBytes) + ")");
        if (std::memcmp(bytes.data(), "IBSP", 4) != 0) {
            const std::string_view magic(reinterpret_cast<const char*>(bytes.data()), 4);
            throw InputError(name + ": header: magic " + quoted_excerpt(magic) +
                             ", expected 'IBSP' (a Quake III / OpenArena map)");
        }
        const std::int32_t version = i32(4);
        if (version != kVersion)
            throw InputError(name + ": header: version " + std::to_string(version) +
                             ", expected 46 (Quake III / OpenArena IBSP)");
        for (int l = 0; l < kLumps; ++l) {
            const std::int32_t off = i32(8 + 8 * l), len = i32(12 + 8 * l);
            if (off < 0 || len < 0)
                fail_lump(l, "negative offset or length (" + std::to_string(off) + ", " + std::to_string(len) + ")");
            offset[l] = std::uint32_t(off), length[l] = std::uint32_t(len);
        }
        // Every lump, read by this mode or not: a file cut short is refused the same in every mode.
        for (int l = 0; l < kLumps; ++l)
            if (std::uint64_t(offset[l]) + length[l] > bytes.size())
                fail_lump(l, "offset " + std::to_string(offset[l]) + " + length " + std::to_string(length[l]) +
                                 " runs past the end of the file (" + std::to_string(bytes.size()) +
                                 " bytes): truncated");
    }

    /// Checks that lump `l` (inside the file: header()) holds whole records; returns the record count.
    std::size_t records(int l, std::size_t record_bytes) const {
        if (length[l] % record_bytes != 0)
            fail_lump(l,
                      "length " + std::to_string(length[l]) + " is not a multiple of " + std::to_string(record_bytes));
        return length[l] / record_bytes;
    }
    std::size_t at(int l, std::size_t record_bytes, std::size_t i) const { return offset[l] + i * record_bytes; }
};

bool finite3(float a, float b, float c) { return std::isfinite(a) && std::isfinite(b) && std::isfinite(c); }

std::vector<Object> parse_brushes(const Reader& r, BspSummary& sum) {
    const std::size_t shaders = r.records(kShaders, kShaderBytes);
    const std::size_t planes = r.records(kPlanes, kPlaneBytes);
    const std::size_t brushes = r.records(kBrushes, kBrushBytes);
    const std::size_t sides = r.records(kBrushSides, kBrushSideBytes);
    sum.brushes = brushes;
    // First pass: every brush's references, and the work they ask for. q3map2 gives each brush its
    // own run of sides, so a real map refers to each side once; a small file whose brushes all
    // claim the same long run would otherwise take brushes x sides steps.
    std::uint64_t side_refs = 0;
    for (std::size_t b = 0; b < brushes; ++b) {
        const std::size_t at = r.at(kBrushes, kBrushBytes, b);
        const std::int32_t first = r.i32(at), count = r.i32(at + 4), shader = r.i32(at + 8);
        if (shader < 0 || std::size_t(shader) >= shaders)
            r.fail_lump(kBrushes, "brush " + std::to_string(b) + " refers to shader " + std::to_string(shader) +
                                      " of " + std::to_string(shaders) + " in lump 1 (shaders)");
        if (first < 0 || count < 0 || std::uint64_t(first) + std::uint64_t(count) > sides)
            r.fail_lump(kBrushes, "brush " + std::to_string(b) + " refers to brushsides " + std::to_string(first) +
                                      ".." + std::to_string(std::int64_t(first) + count - 1) + " beyond the " +
                                      std::to_string(sides) + " in lump 9 (brushsides)");
        side_refs += std::uint64_t(count);
    }
    if (side_refs > kMaxSceneObjects)
        r.fail_lump(kBrushes, "the brushes refer to " + std::to_string(side_refs) + " brushsides in all (of " +
                                  std::to_string(sides) + "), more than the limit of " +
                                  std::to_string(kMaxSceneObjects) + " (kMaxSceneObjects, scene.h)");
    std::vector<Object> out;
    out.reserve(brushes);
    for (std::size_t b = 0; b < brushes; ++b) {
        const std::size_t at = r.at(kBrushes, kBrushBytes, b);
        const std::int32_t first = r.i32(at), count = r.i32(at + 4), shader = r.i32(at + 8);
        const std::int32_t contents = r.i32(r.at(kShaders, kShaderBytes, std::size_t(shader)) + 68);
        if (!(contents & (kContentsSolid | kContentsPlayerClip))) {
            ++sum.skipped_non_solid;
            continue;
        }
        // Axial sides bound the brush: the brush is {x : n·x <= dist} over its sides.
        constexpr float inf = std::numeric_limits<float>::infinity();
        Aabb box{{-inf, -inf, -inf}, {inf, inf, inf}};
        for (std::int32_t k = 0; k < count; ++k) {
            const std::int32_t plane = r.i32(r.at(kBrushSides, kBrushSideBytes, std::size_t(first + k)));
            if (plane < 0 || std::size_t(plane) >= planes)
                r.fail_lump(kBrushSides, "brushside " + std::to_string(first + k) + " refers to plane " +
                                             std::to_string(plane) + " of " + std::to_string(planes) +
                                             " in lump 2 (planes)");
            const std::size_t p = r.at(kPlanes, kPlaneBytes, std::size_t(plane));
            const float n[3] = {r.f32(p), r.f32(p + 4), r.f32(p + 8)};
            const float dist = r.f32(p + 12);
            if (!finite3(n[0], n[1], n[2]) || !std::isfinite(dist))
                r.fail_lump(kPlanes, "plane " + std::to_string(plane) + " has a non-finite value");
            for (int a = 0; a < 3; ++a) {
                const int o1 = (a + 1) % 3, o2 = (a + 2) % 3;
                if (std::abs(n[o1]) > 1e-6f || std::abs(n[o2]) > 1e-6f || std::abs(std::abs(n[a]) - 1.0f) > 1e-6f)
                    continue;
                if (n[a] > 0)
                    box.max[a] = std::min(box.max[a], dist);
                else
                    box.min[a] = std::max(box.min[a], -dist);
            }
        }
        if (!is_finite(box.min) || !is_finite(box.max) || box.is_empty()) {
            ++sum.skipped_not_closed;
            continue;
        }
        out.push_back(Object{Uid(out.size()), box});
        if (!box_problem(box).empty()) check_object(out.back(), r.name + ": brush " + std::to_string(b));
        ++sum.solid_brushes;
    }
    return out;
}

std::vector<Object> parse_triangles(const Reader& r, std::uint64_t max_triangles, BspSummary& sum) {
    const std::size_t verts = r.records(kDrawVerts, kDrawVertBytes);
    const std::size_t indexes = r.records(kDrawIndexes, kIndexBytes);
    const std::size_t surfaces = r.records(kSurfaces, kSurfaceBytes);
    sum.surfaces = surfaces;
    auto vertex = [&](std::size_t s, std::int64_t v) {
        if (v < 0 || std::uint64_t(v) >= verts)
            r.fail_lump(kSurfaces, "surface " + std::to_string(s) + " refers to vertex " + std::to_string(v) + " of " +
                                       std::to_string(verts) + " in lump 10 (drawverts)");
        const std::size_t at = r.at(kDrawVerts, kDrawVertBytes, std::size_t(v));
        const Vec3 p{r.f32(at), r.f32(at + 4), r.f32(at + 8)};
        if (!is_finite(p)) r.fail_lump(kDrawVerts, "vertex " + std::to_string(v) + " has a non-finite coordinate");
        return p;
    };
    // int shader, fog, type, firstVert, numVerts, firstIndex, numIndexes, lightmapNum, lightmapX,
    // lightmapY, lightmapWidth, lightmapHeight; float lightmapOrigin[3], lightmapVecs[2][3],
    // normal[3]; int patchWidth, patchHeight.
    struct Header {
        std::int32_t type, first_vert, num_verts, first_index, num_indexes, w, h;
    };
    auto header = [&](std::size_t s) {
        const std::size_t at = r.at(kSurfaces, kSurfaceBytes, s);
        return Header{r.i32(at + 8),  r.i32(at + 12), r.i32(at + 16), r.i32(at + 20),
                      r.i32(at + 24), r.i32(at + 96), r.i32(at + 100)};
    };
    // First pass: check every surface's counts and add up the triangles before allocating any.
    // Surfaces may share vertices and indexes, so a small file can describe billions of triangles
    // (every patch naming the same large grid); the count is exact, so the check is too.
    std::uint64_t estimate = 0;
    for (std::size_t s = 0; s < surfaces; ++s) {
        const Header h = header(s);
        if (h.type == kPlanar || h.type == kTriangleSoup) {
            if (h.first_index < 0 || h.num_indexes < 0 ||
                std::uint64_t(h.first_index) + std::uint64_t(h.num_indexes) > indexes)
                r.fail_lump(kSurfaces, "surface " + std::to_string(s) + " refers to drawindexes beyond the " +
                                           std::to_string(indexes) + " in lump 11 (drawindexes)");
            if (h.num_indexes % 3 != 0)
                r.fail_lump(kSurfaces, "surface " + std::to_string(s) + " has " + std::to_string(h.num_indexes) +
                                           " indexes, not a multiple of 3");
            estimate += std::uint64_t(h.num_indexes / 3);
        } else if (h.type == kPatch) {
            if (h.w < 0 || h.h < 0 || std::int64_t(h.w) * h.h != h.num_verts)
                r.fail_lump(kSurfaces, "patch surface " + std::to_string(s) + " is " + std::to_string(h.w) + "x" +
                                           std::to_string(h.h) + " but has " + std::to_string(h.num_verts) +
                                           " vertices");
            if (h.w > 0 && h.h > 0) estimate += 2 * std::uint64_t(h.w - 1) * std::uint64_t(h.h - 1);
        }
    }
    if (estimate > kMaxSceneObjects)
        throw InputError(r.name + ": triangles mode would make " + std::to_string(estimate) +
                         " triangles, more than the limit of " + std::to_string(kMaxSceneObjects) +
                         " objects per scene (kMaxSceneObjects, scene.h); try --bsp-mode brushes");
    if (estimate > max_triangles)
        throw InputError(r.name + ": triangles mode would make " + std::to_string(estimate) + " triangles (" +
                         std::to_string((estimate * sizeof(Object) + (1 << 20) - 1) >> 20) +
                         " MiB of objects before any structure), more than the budget of " +
                         std::to_string(max_triangles) +
                         "; raise it with --bsp-max-triangles (import_options.bsp_max_triangles in an experiment)");
    std::vector<Object> out;
    out.reserve(estimate);
    std::size_t s = 0;
    // Each object is its triangle (shape.h), the box its bounds; degenerate triangles stay (they
    // are valid shapes, met edge-on or not at all). vertex() has rejected non-finite coordinates.
    auto triangle = [&](Vec3 a, Vec3 b, Vec3 c) {
        out.push_back(shaped_object(Uid(out.size()), Shape::triangle(a, b, c)));
        // The box is the vertices' exact bounds: its check names a coordinate out of range.
        if (!box_problem(out.back().box).empty())
            check_object(Object{out.back().uid, out.back().box}, r.name + ": surface " + std::to_string(s));
    };
    for (; s < surfaces; ++s) {
        const auto [type, first_vert, num_verts, first_index, num_indexes, w, h] = header(s);
        if (type == kPlanar || type == kTriangleSoup) {
            for (std::int32_t k = 0; k < num_indexes; k += 3) {
                Vec3 p[3];
                for (int j = 0; j < 3; ++j)
                    p[j] = vertex(s, std::int64_t(first_vert) +
                                         r.i32(r.at(kDrawIndexes, kIndexBytes, std::size_t(first_index + k + j))));
                triangle(p[0], p[1], p[2]);
            }
        } else if (type == kPatch) {
            for (std::int32_t y = 0; y + 1 < h; ++y)
                for (std::int32_t x = 0; x + 1 < w; ++x) {
                    const std::int64_t v00 = std::int64_t(first_vert) + y * w + x;
                    const Vec3 a = vertex(s, v00), b = vertex(s, v00 + 1), c = vertex(s, v00 + w),
                               d = vertex(s, v00 + w + 1);
                    triangle(a, b, d);
                    triangle(a, d, c);
                }
        }
    }
    sum.triangles = out.size();
    return out;
}

/// A name from the file (a zip entry) as messages show it: as is when it is short printable ASCII,
/// else quoted and escaped.
std::string shown(const std::string& name) {
    const bool plain =
        name.size() <= 80 && std::all_of(name.begin(), name.end(), [](char c) { return c >= 0x20 && c < 0x7f; });
    return plain ? name : quoted_excerpt(name);
}

std::string lower(std::string s) {
    for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
    return s;
}

std::string zip_message(int code) {
    zip_error_t e;
    zip_error_init_with_code(&e, code);
    std::string m = zip_error_strerror(&e);
    zip_error_fini(&e);
    return m;
}

struct Zip {
    zip_t* z = nullptr;
    explicit Zip(const std::string& path) {
        int err = 0;
        z = zip_open(path.c_str(), ZIP_RDONLY, &err);
        if (!z) throw InputError(path + ": not a readable zip (.pk3): " + zip_message(err));
    }
    ~Zip() {
        if (z) zip_discard(z);
    }
    Zip(const Zip&) = delete;
    Zip& operator=(const Zip&) = delete;
};

void check_map_size(std::uint64_t bytes, const std::string& name) {
    if (bytes > kMaxMapBytes)
        throw InputError(name + ": " + std::to_string(bytes) + " bytes, more than the limit of " +
                         std::to_string(kMaxMapBytes) + " for a map (kMaxMapBytes, bsp.h)");
}

std::vector<std::uint8_t> read_file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    if (!in) throw InputError(path + ": cannot open");
    const std::streamoff size = in.tellg();
    if (size < 0) throw InputError(path + ": cannot read its size");
    check_map_size(std::uint64_t(size), path);
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(size));
    in.seekg(0);
    if (!bytes.empty() && !in.read(reinterpret_cast<char*>(bytes.data()), size))
        throw InputError(path + ": read failed");
    return bytes;
}

}  // namespace

std::vector<Object> parse_bsp(std::span<const std::uint8_t> bytes, const std::string& name, const std::string& mode,
                              BspSummary* summary, std::uint64_t max_triangles) {
    if (mode != "brushes" && mode != "triangles")
        throw InputError(name + ": bsp mode '" + mode + "': expected brushes or triangles");
    Reader r{bytes, name, {}, {}};
    r.header();
    BspSummary local;
    BspSummary& sum = summary ? *summary : local;
    return mode == "brushes" ? parse_brushes(r, sum) : parse_triangles(r, max_triangles, sum);
}

std::vector<std::string> pk3_maps(const std::string& path) {
    Zip zip(path);
    std::vector<std::string> maps;
    const zip_int64_t n = zip_get_num_entries(zip.z, 0);
    for (zip_int64_t i = 0; i < n; ++i) {
        const char* entry = zip_get_name(zip.z, zip_uint64_t(i), 0);
        if (!entry) continue;
        const std::string l = lower(entry);
        if (l.rfind("maps/", 0) == 0 && l.size() > 9 && l.substr(l.size() - 4) == ".bsp" &&
            l.find('/', 5) == std::string::npos)
            maps.push_back(entry);
    }
    std::sort(maps.begin(), maps.end());
    return maps;
}

std::vector<std::uint8_t> read_zip_entry(const std::string& path, const std::string& entry) {
    Zip zip(path);
    const zip_int64_t index = zip_name_locate(zip.z, entry.c_str(), ZIP_FL_NOCASE);
    const std::string where = path + ":" + shown(entry);
    if (index < 0) throw InputError(path + ": no entry " + shown(entry));
    zip_stat_t st;
    if (zip_stat_index(zip.z, zip_uint64_t(index), 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE))
        throw InputError(where + ": cannot read its size: " + zip_strerror(zip.z));
    check_map_size(st.size, where);
    zip_file_t* f = zip_fopen_index(zip.z, zip_uint64_t(index), 0);
    if (!f) throw InputError(where + ": cannot open: " + zip_strerror(zip.z));
    std::vector<std::uint8_t> bytes(st.size);
    const zip_int64_t got = bytes.empty() ? 0 : zip_fread(f, bytes.data(), bytes.size());
    const std::string err = got < 0 ? zip_file_strerror(f) : "";
    zip_fclose(f);
    if (got < 0 || zip_uint64_t(got) != st.size)
        throw InputError(where + ": read " + std::to_string(got) + " of " + std::to_string(st.size) + " bytes" +
                         (err.empty() ? "" : ": " + err));
    return bytes;
}

std::vector<Object> import_bsp(const std::string& path, const BspOptions& options, BspSummary* summary) {
    const std::string ext = lower(std::filesystem::path(path).extension().string());
    BspSummary local;
    BspSummary& sum = summary ? *summary : local;
    if (ext == ".pk3" || ext == ".zip") {
        const std::vector<std::string> maps = pk3_maps(path);
        // The maps' names for messages; a pk3 may hold thousands (and any bytes in a name).
        std::string list;
        for (std::size_t i = 0; i < maps.size() && i < 20; ++i)
            list += (i ? ", " : "") + shown(std::filesystem::path(maps[i]).stem().string());
        if (maps.size() > 20) list += ", … (" + std::to_string(maps.size()) + " in all)";
        if (maps.empty()) throw InputError(path + ": no maps/*.bsp inside");
        std::string entry;
        if (options.map.empty()) {
            if (maps.size() != 1)
                throw InputError(path + ": holds " + std::to_string(maps.size()) + " maps, choose one with --map (" +
                                 list + ")");
            entry = maps.front();
        } else {
            for (const std::string& m : maps)
                if (lower(m) == lower(options.map) || lower(m) == "maps/" + lower(options.map) + ".bsp") entry = m;
            if (entry.empty())
                throw InputError(path + ": no map " + quoted_excerpt(options.map) + " inside (maps: " + list + ")");
        }
        const std::vector<std::uint8_t> bytes = read_zip_entry(path, entry);
        sum.map = entry;
        return parse_bsp(bytes, std::filesystem::path(path).filename().string() + ":" + shown(entry), options.mode,
                         &sum, options.max_triangles);
    }
    if (!options.map.empty()) throw InputError(path + ": --map is for a .pk3; a .bsp is one map");
    const std::vector<std::uint8_t> bytes = read_file_bytes(path);
    sum.map = std::filesystem::path(path).filename().string();
    return parse_bsp(bytes, path, options.mode, &sum, options.max_triangles);
}

Aabb bsp_box_in_metres(const Aabb& box) {
    const Vec3d lo = box.min.as<double>() * kBspUnitMetres, hi = box.max.as<double>() * kBspUnitMetres;
    return Aabbd{{lo.x, lo.z, -hi.y}, {hi.x, hi.z, -lo.y}}.as<float>();
}

}  // namespace rcb
