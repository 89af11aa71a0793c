// Importers: Quake III / OpenArena BSP (a tiny map built here, byte by byte; pk3 as a stored zip
// built here), assimp models (a tiny OBJ and glTF written here), the dispatch by extension, the
// CLI, and the real OpenArena maps when scripts/fetch_maps.sh has fetched them.
#include <gtest/gtest.h>

#include <pthread.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <functional>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/import/csv.h"
#include "core/scene/recording_io.h"
#include "core/scene/import/bsp.h"
#include "core/scene/import/model.h"
#include "core/scene/import/nesting.h"
#include "core/scene/import/scene_import.h"
#include "runner/experiment.h"
#include "tests/subprocess.h"
#include "tests/test_scenes.h"
#include "tests/real_data.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::uint8_t>;

void put_i32(Bytes& b, std::int32_t v) {
    const auto* p = reinterpret_cast<const std::uint8_t*>(&v);
    b.insert(b.end(), p, p + 4);
}
void put_u16(Bytes& b, std::uint16_t v) {
    b.push_back(std::uint8_t(v & 0xff));
    b.push_back(std::uint8_t(v >> 8));
}
void put_f32(Bytes& b, float v) {
    std::int32_t i;
    std::memcpy(&i, &v, 4);
    put_i32(b, i);
}

/// A tiny IBSP 46 map, lump by lump.
struct TinyBsp {
    std::array<Bytes, 17> lump;
    std::int32_t version = 46;

    void shader(const char* name, std::int32_t contents) {
        Bytes& b = lump[1];
        char n[64] = {};
        std::strncpy(n, name, 63);
        b.insert(b.end(), n, n + 64);
        put_i32(b, 0);
        put_i32(b, contents);
    }
    std::int32_t plane(float nx, float ny, float nz, float d) {
        put_f32(lump[2], nx), put_f32(lump[2], ny), put_f32(lump[2], nz), put_f32(lump[2], d);
        return std::int32_t(lump[2].size() / 16 - 1);
    }
    /// A brush of the box [lo, hi] (axial sides only where `axes` says, plus one bevel).
    void brush(Vec3 lo, Vec3 hi, std::int32_t shader, int axes = 3) {
        const std::int32_t first = std::int32_t(lump[9].size() / 8);
        std::int32_t count = 0;
        auto side = [&](std::int32_t p) {
            put_i32(lump[9], p), put_i32(lump[9], shader);
            ++count;
        };
        for (int a = 0; a < axes; ++a) {
            float n[3] = {0, 0, 0};
            n[a] = 1;
            side(plane(n[0], n[1], n[2], hi[a]));
            n[a] = -1;
            side(plane(n[0], n[1], n[2], -lo[a]));
        }
        side(plane(0.70710677f, 0.70710677f, 0, 1000));  // a bevel: not axial, ignored
        put_i32(lump[8], first), put_i32(lump[8], count), put_i32(lump[8], shader);
    }
    void vertex(Vec3 p) {
        Bytes& b = lump[10];
        put_f32(b, p.x), put_f32(b, p.y), put_f32(b, p.z);
        for (int i = 0; i < 7; ++i) put_f32(b, 0);  // st, lightmap, normal
        put_i32(b, -1);                             // color
    }
    void surface(std::int32_t type, std::int32_t first_vert, std::int32_t num_verts, std::int32_t first_index,
                 std::int32_t num_indexes, std::int32_t pw = 0, std::int32_t ph = 0) {
        Bytes& b = lump[13];
        for (std::int32_t v : {0, -1, type, first_vert, num_verts, first_index, num_indexes, 0, 0, 0, 0, 0})
            put_i32(b, v);
        for (int i = 0; i < 12; ++i) put_f32(b, 0);  // lightmap origin, vecs, normal
        put_i32(b, pw), put_i32(b, ph);
    }
    Bytes bytes() const {
        Bytes b{'I', 'B', 'S', 'P'};
        put_i32(b, version);
        std::int32_t offset = 8 + 17 * 8;
        for (const Bytes& l : lump) {
            put_i32(b, offset), put_i32(b, std::int32_t(l.size()));
            offset += std::int32_t(l.size());
        }
        for (const Bytes& l : lump) b.insert(b.end(), l.begin(), l.end());
        return b;
    }
};

/// Solid brush [0,0,0]-[1,2,3], player-clip brush [-4,-4,-4]-[-2,-3,-1], a water brush (skipped),
/// a solid brush without z sides (skipped); a planar quad (2 triangles), a 3x3 patch (8 triangles)
/// and a billboard (skipped).
TinyBsp tiny_map() {
    TinyBsp m;
    m.lump[0] = {'{', '}', 0};
    m.shader("textures/base/solid", 0x1);
    m.shader("textures/liquids/water", 0x20);
    m.shader("common/clip", 0x10000);
    m.brush({0, 0, 0}, {1, 2, 3}, 0);
    m.brush({-4, -4, -4}, {-2, -3, -1}, 2);
    m.brush({5, 5, 5}, {6, 6, 6}, 1);
    m.brush({8, 8, 8}, {9, 9, 9}, 0, 2);
    for (Vec3 p : {Vec3{0, 0, 0}, Vec3{1, 0, 0}, Vec3{1, 1, 0}, Vec3{0, 1, 0}}) m.vertex(p);
    for (std::int32_t i : {0, 1, 2, 0, 2, 3}) put_i32(m.lump[11], i);
    m.surface(1, 0, 4, 0, 6);
    for (int y = 0; y < 3; ++y)
        for (int x = 0; x < 3; ++x) m.vertex({float(x), float(y), float((x + y) % 2)});
    m.surface(2, 4, 9, 0, 0, 3, 3);
    m.surface(4, 0, 1, 0, 0);
    return m;
}

std::string write_file(const fs::path& path, const Bytes& bytes) {
    fs::create_directories(path.parent_path());
    std::ofstream out(path, std::ios::binary);
    out.write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
    return path.string();
}
std::string write_text(const fs::path& path, const std::string& text) {
    return write_file(path, Bytes(text.begin(), text.end()));
}

fs::path scratch(const std::string& name) {
    static const test::TempDir dir("importers", "scratch");  // removed when the process ends
    return dir.path() / name;
}

std::uint32_t crc32(const Bytes& data) {
    std::uint32_t c = 0xFFFFFFFFu;
    for (std::uint8_t byte : data) {
        c ^= byte;
        for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
    }
    return ~c;
}

/// A zip with stored (uncompressed) entries, as a minimal .pk3.
Bytes stored_zip(const std::vector<std::pair<std::string, Bytes>>& entries) {
    Bytes z, central;
    for (const auto& [name, data] : entries) {
        const std::uint32_t offset = std::uint32_t(z.size()), crc = crc32(data), size = std::uint32_t(data.size());
        put_i32(z, 0x04034b50);
        put_u16(z, 20), put_u16(z, 0), put_u16(z, 0), put_u16(z, 0), put_u16(z, 0x21);
        put_i32(z, std::int32_t(crc)), put_i32(z, std::int32_t(size)), put_i32(z, std::int32_t(size));
        put_u16(z, std::uint16_t(name.size())), put_u16(z, 0);
        z.insert(z.end(), name.begin(), name.end());
        z.insert(z.end(), data.begin(), data.end());
        put_i32(central, 0x02014b50);
        put_u16(central, 20), put_u16(central, 20), put_u16(central, 0), put_u16(central, 0), put_u16(central, 0),
            put_u16(central, 0x21);
        put_i32(central, std::int32_t(crc)), put_i32(central, std::int32_t(size)), put_i32(central, std::int32_t(size));
        put_u16(central, std::uint16_t(name.size())), put_u16(central, 0), put_u16(central, 0), put_u16(central, 0),
            put_u16(central, 0);
        put_i32(central, 0), put_i32(central, std::int32_t(offset));
        central.insert(central.end(), name.begin(), name.end());
    }
    const std::uint32_t cd_offset = std::uint32_t(z.size());
    z.insert(z.end(), central.begin(), central.end());
    put_i32(z, 0x06054b50);
    put_u16(z, 0), put_u16(z, 0), put_u16(z, std::uint16_t(entries.size())), put_u16(z, std::uint16_t(entries.size()));
    put_i32(z, std::int32_t(central.size())), put_i32(z, std::int32_t(cd_offset)), put_u16(z, 0);
    return z;
}

std::string error_of(const std::function<void()>& f) { return test::input_error_of(f); }

Aabb box(float x0, float y0, float z0, float x1, float y1, float z1) { return {{x0, y0, z0}, {x1, y1, z1}}; }

/// A glTF 2.0 file: `nodes` (a JSON array), the scene's root list, and one triangle mesh
/// (0,0,0) (1,0,0) (0,1,0) as mesh 0; `extras` goes into the top-level object.
std::string gltf_text(const std::string& nodes, const std::string& roots = "[0]", const std::string& extras = "") {
    return R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": )" + roots + R"(}], "nodes": )" + nodes +
           R"(, "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}])" +
           (extras.empty() ? "" : ", \"extras\": " + extras) + "}";
}

/// A chain of `depth` nodes, each the only child of the one before and translated by (1,0,0);
/// the last holds the mesh, so its triangle lands at x = depth.
std::string gltf_chain(std::size_t depth) {
    std::string nodes = "[";
    for (std::size_t i = 0; i + 1 < depth; ++i)
        nodes += R"({"translation": [1, 0, 0], "children": [)" + std::to_string(i + 1) + "]},";
    return gltf_text(nodes + R"({"translation": [1, 0, 0], "mesh": 0}])");
}

/// A COLLADA document with one triangle geometry "g", the visual scene's body, and a node library.
std::string collada_text(const std::string& scene, const std::string& library = "") {
    return R"(<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
<library_geometries><geometry id="g"><mesh><source id="p"><float_array id="pa" count="9">0 0 0 1 0 0 0 1 0</float_array>
<technique_common><accessor source="#pa" count="3" stride="3"><param name="X" type="float"/><param name="Y" type="float"/>
<param name="Z" type="float"/></accessor></technique_common></source><vertices id="v"><input semantic="POSITION" source="#p"/>
</vertices><triangles count="1"><input semantic="VERTEX" source="#v" offset="0"/><p>0 1 2</p></triangles></mesh></geometry>
</library_geometries>)" +
           library + R"(<library_visual_scenes><visual_scene id="s">)" + scene +
           R"(</visual_scene></library_visual_scenes><scene><instance_visual_scene url="#s"/></scene></COLLADA>)";
}

/// `depth` nested <node> elements, the innermost holding the triangle, each translated by (1,0,0).
std::string collada_chain(std::size_t depth) {
    std::string open, close;
    for (std::size_t i = 0; i < depth; ++i) {
        open += "<node id=\"n" + std::to_string(i) + "\"><translate>1 0 0</translate>";
        close += "</node>";
    }
    return collada_text(open + "<instance_geometry url=\"#g\"/>" + close);
}

/// Runs f on a thread with a small stack (as a caller deep in its own recursion would): the
/// importer must not put assimp's recursion on its caller's stack.
void on_small_stack(std::size_t bytes, const std::function<void()>& f) {
    struct Job {
        const std::function<void()>* f;
        std::exception_ptr error;
    } job{&f, nullptr};
    pthread_attr_t attr;
    ASSERT_EQ(pthread_attr_init(&attr), 0);
    ASSERT_EQ(pthread_attr_setstacksize(&attr, bytes), 0);
    pthread_t t;
    ASSERT_EQ(pthread_create(
                  &t, &attr,
                  [](void* p) -> void* {
                      auto* j = static_cast<Job*>(p);
                      try {
                          (*j->f)();
                      } catch (...) {
                          j->error = std::current_exception();
                      }
                      return nullptr;
                  },
                  &job),
              0);
    pthread_attr_destroy(&attr);
    pthread_join(t, nullptr);
    if (job.error) std::rethrow_exception(job.error);
}

}  // namespace

TEST(BspImport, OneBoxPerSolidBrushFromItsAxialSides) {
    const Bytes bytes = tiny_map().bytes();
    BspSummary s;
    const std::vector<Object> objects = parse_bsp(bytes, "tiny.bsp", "brushes", &s);
    ASSERT_EQ(objects.size(), 2u);
    EXPECT_EQ(objects[0], (Object{0, box(0, 0, 0, 1, 2, 3)}));
    EXPECT_EQ(objects[1], (Object{1, box(-4, -4, -4, -2, -3, -1)}));  // player clip counts as solid
    EXPECT_EQ(s.brushes, 4u);
    EXPECT_EQ(s.skipped_non_solid, 1u);   // water
    EXPECT_EQ(s.skipped_not_closed, 1u);  // no z sides
}

TEST(BspImport, OneBoxPerDrawSurfaceTriangle) {
    const Bytes bytes = tiny_map().bytes();
    const std::vector<Object> objects = parse_bsp(bytes, "tiny.bsp", "triangles");
    ASSERT_EQ(objects.size(), 2u + 8u);  // the quad's 2, the 3x3 patch's 2x2 cells x 2, no billboard
    EXPECT_EQ(objects[0].box, box(0, 0, 0, 1, 1, 0));
    EXPECT_EQ(objects[1].box, box(0, 0, 0, 1, 1, 0));
    EXPECT_EQ(objects[2].box, box(0, 0, 0, 1, 1, 1));  // patch cell (0,0): (0,0,0) (1,0,1) (1,1,0)
    for (std::size_t i = 0; i < objects.size(); ++i) {
        EXPECT_EQ(objects[i].uid, i);
        // Each object is its triangle, and its box is the triangle's bounds.
        EXPECT_EQ(objects[i].shape.kind, ShapeKind::triangle);
        EXPECT_EQ(objects[i].box, shape_bounds(objects[i].shape));
    }
    EXPECT_EQ(objects[2].shape, Shape::triangle({0, 0, 0}, {1, 0, 1}, {1, 1, 0}));
    // Brushes stay boxes.
    for (const Object& o : parse_bsp(bytes, "tiny.bsp", "brushes")) EXPECT_EQ(o.shape.kind, ShapeKind::box);
}

TEST(BspImport, ErrorsNameTheFileAndTheLump) {
    TinyBsp m = tiny_map();
    m.version = 47;
    EXPECT_EQ(error_of([&] { parse_bsp(m.bytes(), "v47.bsp", "brushes"); }),
              "v47.bsp: header: version 47, expected 46 (Quake III / OpenArena IBSP)");

    Bytes bytes = tiny_map().bytes();
    bytes.resize(bytes.size() - 40);  // cuts into the last lumps
    const std::string truncated = error_of([&] { parse_bsp(bytes, "cut.bsp", "triangles"); });
    EXPECT_NE(truncated.find("cut.bsp: lump 13 (surfaces): offset"), std::string::npos) << truncated;
    EXPECT_NE(truncated.find("runs past the end of the file"), std::string::npos) << truncated;

    EXPECT_NE(error_of([&] { parse_bsp(Bytes(20, 0), "short.bsp", "brushes"); }).find("short.bsp: header: truncated"),
              std::string::npos);
    EXPECT_NE(
        error_of([&] { parse_bsp(Bytes(200, 'x'), "junk.bsp", "brushes"); }).find("junk.bsp: header: magic 'xxxx'"),
        std::string::npos);

    TinyBsp odd = tiny_map();
    odd.lump[8].push_back(0);
    EXPECT_EQ(error_of([&] { parse_bsp(odd.bytes(), "odd.bsp", "brushes"); }),
              "odd.bsp: lump 8 (brushes): length 49 is not a multiple of 12");

    TinyBsp bad = tiny_map();
    std::int32_t big = 1000;
    std::memcpy(bad.lump[8].data() + 4, &big, 4);  // brush 0 claims 1000 sides
    const std::string sides = error_of([&] { parse_bsp(bad.bytes(), "bad.bsp", "brushes"); });
    EXPECT_NE(sides.find("bad.bsp: lump 8 (brushes): brush 0 refers to brushsides 0..999 beyond the"),
              std::string::npos)
        << sides;

    TinyBsp badv = tiny_map();
    std::int32_t far_vertex = 500;
    std::memcpy(badv.lump[11].data(), &far_vertex, 4);
    const std::string verts = error_of([&] { parse_bsp(badv.bytes(), "badv.bsp", "triangles"); });
    EXPECT_NE(verts.find("badv.bsp: lump 13 (surfaces): surface 0 refers to vertex 500"), std::string::npos) << verts;

    EXPECT_NE(error_of([&] { parse_bsp(tiny_map().bytes(), "m.bsp", "faces"); }).find("expected brushes or triangles"),
              std::string::npos);
}

TEST(BspImport, ReadsMapsFromAPk3) {
    const Bytes map = tiny_map().bytes();
    TinyBsp other = tiny_map();
    other.brush({10, 10, 10}, {11, 11, 11}, 0);
    const std::string one =
        write_file(scratch("one.pk3"), stored_zip({{"readme.txt", Bytes{'h', 'i'}}, {"maps/tiny.bsp", map}}));
    const std::string two =
        write_file(scratch("two.pk3"), stored_zip({{"maps/a.bsp", map}, {"maps/b.bsp", other.bytes()}}));
    EXPECT_EQ(pk3_maps(two), (std::vector<std::string>{"maps/a.bsp", "maps/b.bsp"}));
    EXPECT_EQ(import_bsp(one, {}).size(), 2u);
    EXPECT_EQ(import_bsp(two, {"brushes", "b"}).size(), 3u);
    EXPECT_EQ(import_bsp(two, {"brushes", "maps/a.bsp"}).size(), 2u);
    EXPECT_EQ(import_bsp(two, {"triangles", "a"}).size(), 10u);
    EXPECT_NE(error_of([&] { import_bsp(two, {}); }).find("holds 2 maps, choose one with --map (a, b)"),
              std::string::npos);
    EXPECT_NE(error_of([&] {
                  import_bsp(two, {"brushes", "c"});
              }).find("no map 'c' inside (maps: a, b)"),
              std::string::npos);
    const std::string junk = write_text(scratch("junk.pk3"), "not a zip at all");
    EXPECT_NE(error_of([&] { import_bsp(junk, {}); }).find("junk.pk3: not a readable zip"), std::string::npos);
    // A broken map inside a pk3 names the pk3, the entry and the lump.
    TinyBsp odd = tiny_map();
    odd.lump[2].push_back(0);
    const std::string bad = write_file(scratch("bad.pk3"), stored_zip({{"maps/odd.bsp", odd.bytes()}}));
    EXPECT_EQ(error_of([&] { import_bsp(bad, {}); }),
              "bad.pk3:maps/odd.bsp: lump 2 (planes): length 417 is not a multiple of 16");
}

TEST(BspImport, SceneMapsListsAPk3sMapsByTheNameImportTakes) {
    const Bytes map = tiny_map().bytes();
    TinyBsp other = tiny_map();
    other.brush({10, 10, 10}, {11, 11, 11}, 0);
    const std::string pk3 = write_file(scratch("list.pk3"), stored_zip({{"maps/my map.bsp", other.bytes()},
                                                                        {"readme.txt", Bytes{'h', 'i'}},
                                                                        {"maps/a.bsp", map},
                                                                        {"maps/odd\x01.bsp", map}}));
    const std::string bin = RCBENCH_BINARY;
    const ::test::Outcome listed = ::test::run_shell(bin + " scene maps " + pk3);
    EXPECT_EQ(listed.code, 0) << listed.err;
    // Sorted, only maps/*.bsp; a name with a control byte (libzip reads a name without the UTF-8
    // flag as code page 437) is shown escaped, as messages show it.
    std::istringstream lines(listed.out);
    std::vector<std::string> names;
    for (std::string line; std::getline(lines, line);) names.push_back(line);
    ASSERT_EQ(names.size(), 3u) << listed.out;
    EXPECT_EQ(names[0], "a");
    EXPECT_EQ(names[1], "my map");
    EXPECT_EQ(names[2].rfind("'odd\\x", 0), 0u) << names[2];
    // A listed name imports as it is.
    EXPECT_EQ(import_bsp(pk3, {"brushes", names[1]}).size(), 3u);
    const std::string junk = write_text(scratch("list-junk.pk3"), "not a zip at all");
    const ::test::Outcome bad = ::test::run_shell(bin + " scene maps " + junk);
    EXPECT_EQ(bad.code, 2);
    EXPECT_NE(bad.err.find("list-junk.pk3: not a readable zip"), std::string::npos) << bad.err;
}

TEST(BspImport, MapBoxesInMetresWithYUp) {
    // x stays, the map's z becomes y, its y becomes -z; 0.0254 m a unit.
    const Aabb m = bsp_box_in_metres(box(0, 100, -10, 100, 200, 300));
    const Aabb want = box(0, -0.254f, -5.08f, 2.54f, 7.62f, -2.54f);
    for (int a = 0; a < 3; ++a) {
        EXPECT_FLOAT_EQ(m.min[a], want.min[a]) << a;
        EXPECT_FLOAT_EQ(m.max[a], want.max[a]) << a;
    }
}

TEST(BspImport, ScenePileDropsBodiesOntoAMap) {
    // A floor 1600 units (40.64 m) square and a post 400 units tall in one corner, so the map's
    // bounds leave room above the floor; in a .pk3 beside another map.
    TinyBsp floor;
    floor.lump[0] = {'{', '}', 0};
    floor.shader("textures/base/solid", 0x1);
    floor.brush({0, 0, -32}, {1600, 1600, 0}, 0);
    floor.brush({1500, 1500, 0}, {1600, 1600, 400}, 0);
    const std::string pk3 = write_file(
        scratch("pile.pk3"), stored_zip({{"maps/floor.bsp", floor.bytes()}, {"maps/tiny.bsp", tiny_map().bytes()}}));
    const std::string out = scratch("pile.rcbscene").string(), bin = RCBENCH_BINARY;
    const std::string gen = bin + " scene gen --objects 40 --frames 60 --rays 10 ";
    const ::test::Outcome ok = ::test::run_shell(gen + "--generator pile --on-map " + pk3 + " --map floor -o " + out);
    ASSERT_EQ(ok.code, 0) << ok.err;
    const Recording r = read_recording(out);
    ASSERT_EQ(r.initial.size(), 42u);
    EXPECT_EQ(r.initial[40].box, bsp_box_in_metres(box(0, 0, -32, 1600, 1600, 0)));
    EXPECT_EQ(r.initial[41].box, bsp_box_in_metres(box(1500, 1500, 0, 1600, 1600, 400)));
    const nlohmann::json meta = nlohmann::json::parse(r.meta);
    EXPECT_EQ(meta["kind"], "pile");
    EXPECT_EQ(meta["on_map"]["map"], "maps/floor.bsp");
    EXPECT_EQ(meta["on_map"]["metres_per_unit"], kBspUnitMetres);
    // Bodies fall: after 1 s every body is lower than it started, none below the floor's top (y = 0).
    LiveSet live(r.initial);
    for (const Frame& f : r.frames) live.apply(f);
    for (Uid u = 0; u < 40; ++u) {
        EXPECT_LT(live.object(u).box.min.y, r.initial[u].box.min.y) << u;
        EXPECT_GT(live.object(u).box.min.y, -0.05f) << u;
    }
    // Refused, exit 2, nothing written: another kind, a file that is not a map, --map alone, no room.
    const std::string csv = write_text(scratch("pile.csv"), "0,0,0,0,1,1,1\n"),
                      none = scratch("none.rcbscene").string();
    const std::string tiny = write_file(scratch("pile-tiny.bsp"), tiny_map().bytes());
    for (const auto& [args, says] : std::vector<std::pair<std::string, std::string>>{
             {"--generator freefall --on-map " + pk3 + " --map floor",
              "--on-map: only --generator pile is dropped onto a map"},
             {"--generator pile --on-map " + csv, "expected a Quake III / OpenArena map"},
             {"--generator pile --map floor", "--map: needs --on-map"},
             {"--generator pile --on-map " + tiny, "pile-tiny.bsp: the map has room for 0 of 40 bodies"}}) {
        const ::test::Outcome o = ::test::run_shell(gen + args + " -o " + none);
        EXPECT_EQ(o.code, 2) << args << ": " << o.err;
        EXPECT_NE(o.err.find(says), std::string::npos) << args << ": " << o.err;
    }
    EXPECT_FALSE(fs::exists(none));
}

TEST(ModelImport, ObjInstancesAndTriangles) {
    const std::string obj = write_text(scratch("two.obj"),
                                       "o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"
                                       "o tri\nv 2 2 2\nv 3 2 2\nv 2 3 4\nf 5 6 7\n");
    ModelSummary s;
    std::vector<Object> instances = import_model(obj, "instances", &s);
    ASSERT_EQ(instances.size(), 2u);
    std::sort(instances.begin(), instances.end(),
              [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    EXPECT_EQ(instances[0].box, box(0, 0, 0, 1, 1, 0));
    EXPECT_EQ(instances[1].box, box(2, 2, 2, 3, 3, 4));
    const std::vector<Object> triangles = import_model(obj, "triangles", &s);
    EXPECT_EQ(triangles.size(), 3u);  // the quad triangulated, and the triangle
    EXPECT_EQ(s.triangles, 3u);
    for (const Object& o : triangles) {
        EXPECT_EQ(o.shape.kind, ShapeKind::triangle);
        EXPECT_EQ(o.box, shape_bounds(o.shape));
    }
    EXPECT_NE(std::find_if(triangles.begin(), triangles.end(),
                           [](const Object& o) {
                               return o.shape == Shape::triangle({2, 2, 2}, {3, 2, 2}, {2, 3, 4});
                           }),
              triangles.end());
    for (const Object& o : instances) EXPECT_EQ(o.shape.kind, ShapeKind::box);
}

TEST(ModelImport, DegenerateTrianglesStayAndNonFiniteVerticesAreNamed) {
    // A triangle with two equal vertices is a valid (degenerate) shape: kept.
    const std::string flat = write_text(scratch("flat.obj"), "o line\nv 0 0 0\nv 1 0 0\nv 1 0 0\nf 1 2 3\n");
    const std::vector<Object> kept = import_model(flat, "triangles");
    ASSERT_EQ(kept.size(), 1u);
    EXPECT_EQ(kept[0].shape, Shape::triangle({0, 0, 0}, {1, 0, 0}, {1, 0, 0}));
    // A vertex whose transforms overflow float (1e30 x 1e30) is not finite in world space: an
    // error naming the file and the node.
    const std::string gltf = R"({
      "asset": {"version": "2.0"},
      "scene": 0, "scenes": [{"nodes": [0]}],
      "nodes": [{"scale": [1e30, 1e30, 1e30], "children": [1]}, {"name": "huge", "mesh": 0, "scale": [1e30, 1e30, 1e30]}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]
    })";
    const std::string scaled = write_text(scratch("scaled.gltf"), gltf);
    const std::string e = error_of([&] { import_model(scaled, "triangles"); });
    EXPECT_NE(e.find("scaled.gltf: node 'huge'"), std::string::npos) << e;
    EXPECT_NE(e.find("non-finite vertex"), std::string::npos) << e;
    EXPECT_EQ(std::count(e.begin(), e.end(), '\n'), 0) << e;
}

TEST(ModelImport, GltfNodeTransformsPlaceEachInstanceInWorldSpace) {
    // One triangle mesh (0,0,0) (1,0,0) (0,1,0) used by two nodes: translated by (10,0,0), and
    // scaled by 2 under a parent translated by (0,0,5). Buffer: 3 float3 positions, base64.
    const std::string gltf = R"({
      "asset": {"version": "2.0"},
      "scene": 0, "scenes": [{"nodes": [0, 1]}],
      "nodes": [{"mesh": 0, "translation": [10, 0, 0]}, {"translation": [0, 0, 5], "children": [2]}, {"mesh": 0, "scale": [2, 2, 2]}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]
    })";
    const std::string path = write_text(scratch("two.gltf"), gltf);
    std::vector<Object> objects = import_model(path, "instances");
    ASSERT_EQ(objects.size(), 2u);
    std::sort(objects.begin(), objects.end(),
              [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    EXPECT_EQ(objects[0].box, box(0, 0, 5, 2, 2, 5));
    EXPECT_EQ(objects[1].box, box(10, 0, 0, 11, 1, 0));
    // Triangles mode: each instance's triangle in world space, the same transforms applied.
    std::vector<Object> triangles = import_model(path, "triangles");
    ASSERT_EQ(triangles.size(), 2u);
    std::sort(triangles.begin(), triangles.end(),
              [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    EXPECT_EQ(triangles[0].shape, Shape::triangle({0, 0, 5}, {2, 0, 5}, {0, 2, 5}));
    EXPECT_EQ(triangles[1].shape, Shape::triangle({10, 0, 0}, {11, 0, 0}, {10, 1, 0}));
    for (std::size_t i = 0; i < 2; ++i) EXPECT_EQ(triangles[i].box, objects[i].box);
}

TEST(ModelImport, RotatedInstancesAreOrientedBoxes) {
    // The unit triangle's mesh under a node turned 45 degrees about z (glTF quaternion x, y, z, w)
    // and translated: in obbs mode its object is the oriented box of the mesh's bounds.
    const std::string gltf = R"({
      "asset": {"version": "2.0"},
      "scene": 0, "scenes": [{"nodes": [0, 1]}],
      "nodes": [{"mesh": 0, "translation": [10, 0, 0], "rotation": [0, 0, 0.38268343, 0.92387953]}, {"mesh": 0}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}],
      "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]
    })";
    const std::string path = write_text(scratch("rotated.gltf"), gltf);
    for (const Object& o : import_model(path, "instances")) EXPECT_EQ(o.shape.kind, ShapeKind::box);
    std::vector<Object> objects = import_model(path, "obbs");
    ASSERT_EQ(objects.size(), 2u);
    std::sort(objects.begin(), objects.end(),
              [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    EXPECT_EQ(objects[0].shape.kind, ShapeKind::box);  // not rotated: the box
    ASSERT_EQ(objects[1].shape.kind, ShapeKind::obb);  // turned 45 degrees about z
    const Shape& obb = objects[1].shape;
    EXPECT_NEAR(obb.v[3], 0.5, 1e-6);
    EXPECT_NEAR(obb.v[4], 0.5, 1e-6);
    EXPECT_EQ(obb.v[5], 0.0f);
    EXPECT_EQ(objects[1].box, shape_bounds(obb));
    // The mesh's local centre (0.5, 0.5, 0) turned by 45 degrees lies on the y axis, at 10 + (0, 0.707).
    EXPECT_NEAR(obb.v[0], 10.0, 1e-5);
    EXPECT_NEAR(obb.v[1], std::sqrt(0.5), 1e-5);
}

TEST(ModelImport, ErrorsNameTheFile) {
    const std::string junk = write_text(scratch("junk.glb"), "glTF but not really");
    const std::string e = error_of([&] { import_model(junk, "instances"); });
    EXPECT_NE(e.find("junk.glb: assimp: "), std::string::npos) << e;
    EXPECT_NE(error_of([&] { import_model(junk, "points"); }).find("expected instances, obbs or triangles"),
              std::string::npos);
}

TEST(SceneImport, DispatchesByExtensionAndValidatesOptions) {
    EXPECT_EQ(importer_for("a.csv"), "csv");
    EXPECT_EQ(importer_for("maps/q3dm1.BSP"), "bsp");
    EXPECT_EQ(importer_for("x.pk3"), "bsp");
    EXPECT_EQ(importer_for("ship.glb"), "model");
    EXPECT_EQ(importer_for("ship.obj"), "model");
    EXPECT_NE(error_of([] { importer_for("notes.txt2"); }).find("notes.txt2: cannot import '.txt2' files"),
              std::string::npos);
    EXPECT_THROW(import_options_from_json({{"mode", "brushes"}}, "scenes[0].import_options"), InputError);
    EXPECT_THROW(import_options_from_json({{"bsp_mode", "faces"}}, "scenes[0].import_options"), InputError);
    EXPECT_EQ(import_options_from_json({{"bsp_mode", "triangles"}, {"map", "oa_dm1"}}, "x").map, "oa_dm1");
    const std::string bsp = write_file(scratch("tiny.bsp"), tiny_map().bytes());
    nlohmann::json meta;
    EXPECT_EQ(import_objects(bsp, {}, &meta).size(), 2u);
    EXPECT_EQ(meta["importer"], "bsp");
    EXPECT_EQ(meta["brushes"]["skipped_non_solid"], 1);
}

TEST(SceneImport, OptionErrorsQuoteAnExcerptOfTheValue) {
    const std::string big(5'000'000, 'x');
    for (const nlohmann::json& j :
         {nlohmann::json{{"bsp_mode", big}}, nlohmann::json{{"model_mode", big}}, nlohmann::json{{big, "a"}},
          nlohmann::json{{"map", std::vector<int>(1'000'000, 7)}}}) {
        const std::string e = error_of([&] { import_options_from_json(j, "scenes[0].import_options"); });
        EXPECT_LT(e.size(), 200u) << e.substr(0, 300);
        EXPECT_EQ(e.rfind("scenes[0].import_options", 0), 0u) << e.substr(0, 300);
    }
    EXPECT_EQ(error_of([] {
                  import_options_from_json({{"bsp_mode", "faces\n"}}, "o");
              }),
              "o.bsp_mode: expected \"brushes\" or \"triangles\", got 'faces\\x0A'");
}

TEST(SceneImport, CliImportsMapsAndModelsAndExitsTwoOnBadFiles) {
    const std::string bsp = write_file(scratch("cli.bsp"), tiny_map().bytes());
    const std::string out = scratch("cli.rcbscene").string();
    const std::string bin = RCBENCH_BINARY;
    EXPECT_EQ(std::system((bin + " scene import " + bsp + " -o " + out +
                           " --frames 2 --rays 10 --bsp-mode triangles > /dev/null")
                              .c_str()),
              0);
    EXPECT_TRUE(fs::exists(out));
    const std::string obj = write_text(scratch("cli.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    EXPECT_EQ(
        std::system(
            (bin + " scene import " + obj + " -o " + out + " --frames 1 --model-mode triangles > /dev/null").c_str()),
        0);
    TinyBsp m = tiny_map();
    m.version = 38;
    const std::string old = write_file(scratch("old.bsp"), m.bytes());
    const std::string err = scratch("err.txt").string();
    const int rc = std::system((bin + " scene import " + old + " -o " + out + " 2> " + err).c_str());
    EXPECT_EQ(WEXITSTATUS(rc), 2);
    std::ifstream in(err);
    std::string line;
    std::getline(in, line);
    EXPECT_NE(line.find("old.bsp: header: version 38"), std::string::npos) << line;
}

TEST(SceneImport, ExperimentFilesImportMapsAndModelsWithOptions) {
    const fs::path bsp = scratch("exp/tiny.bsp");
    write_file(bsp, tiny_map().bytes());
    write_text(scratch("exp/tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    const std::string base = bsp.parent_path().string();
    const std::string text = R"({"name": "t", "frames": 2, "rays_per_frame": 20, "scenes": [
        {"import": "tiny.bsp"}, {"import": "tiny.bsp", "import_options": {"bsp_mode": "triangles"}},
        {"import": "tri.obj", "import_options": {"model_mode": "triangles"}}], "structures": [{"name": "bf"}]})";
    const Experiment e = parse_experiment(text, "t.json", base);
    ASSERT_EQ(e.scenes.size(), 3u);
    EXPECT_NE(e.scenes[0].key, e.scenes[1].key);  // the mode is part of the scene's identity
    EXPECT_EQ(load_scene(e.scenes[0]).initial.size(), 2u);
    EXPECT_EQ(load_scene(e.scenes[1]).initial.size(), 10u);
    const Recording model = load_scene(e.scenes[2]);
    EXPECT_EQ(model.initial.size(), 1u);
    EXPECT_EQ(model.frames.size(), 2u);
    auto bad = [&](const std::string& scene) {
        return error_of([&] {
            parse_experiment(R"({"name": "t", "scenes": [)" + scene + R"(], "structures": [{"name": "bf"}]})", "t.json",
                             base);
        });
    };
    EXPECT_NE(bad(R"({"import": "tiny.bsp", "import_options": {"mode": "x"}})").find("scenes[0].import_options"),
              std::string::npos);
    EXPECT_NE(bad(R"({"import": "tiny.bsp", "import_options": {"bsp_mode": "faces"}})").find("bsp_mode"),
              std::string::npos);
    EXPECT_NE(bad(R"({"preset": "uni-s", "import_options": {}})").find("only an \"import\" scene takes import options"),
              std::string::npos);
}

TEST(BspImport, TriangleCountsAreEstimatedAndLimitedBeforeAllocating) {
    // Surfaces may share vertices: here 3500 patches all name one 100x100 grid, 68.6 million
    // triangles from an 0.8 MB file (such a map ran 13-37 s and ended in std::bad_alloc).
    TinyBsp m;
    m.shader("textures/base/solid", 0x1);
    for (int y = 0; y < 100; ++y)
        for (int x = 0; x < 100; ++x) m.vertex({float(x), float(y), 0});
    for (int s = 0; s < 3500; ++s) m.surface(2, 0, 100 * 100, 0, 0, 100, 100);
    const std::string e = error_of([&] { parse_bsp(m.bytes(), "bomb.bsp", "triangles"); });
    EXPECT_EQ(
        e,
        "bomb.bsp: triangles mode would make 68607000 triangles, more than the limit of 67108864 objects per scene "
        "(kMaxSceneObjects, scene.h); try --bsp-mode brushes");
    // Below the limit the same grid imports (one patch: 2 x 99 x 99 triangles).
    TinyBsp one;
    one.lump[10] = m.lump[10];
    one.surface(2, 0, 100 * 100, 0, 0, 100, 100);
    EXPECT_EQ(parse_bsp(one.bytes(), "one.bsp", "triangles").size(), 2u * 99 * 99);
}

TEST(BspImport, TrianglesBeyondTheBudgetAreRefusedNamingHowToRaiseIt) {
    // 510 patches naming one 100x100 grid: 10 million triangles from a 490 KB file, under the
    // object limit (such a map took 17-23 s and 1.9 GB); refused by the default budget.
    TinyBsp m;
    for (int y = 0; y < 100; ++y)
        for (int x = 0; x < 100; ++x) m.vertex({float(x), float(y), 0});
    for (int s = 0; s < 510; ++s) m.surface(2, 0, 100 * 100, 0, 0, 100, 100);
    const std::uint64_t triangles = 510u * 2 * 99 * 99;
    const std::string mib = std::to_string((triangles * sizeof(Object) + (1 << 20) - 1) >> 20);
    EXPECT_EQ(error_of([&] { parse_bsp(m.bytes(), "bomb.bsp", "triangles"); }),
              "bomb.bsp: triangles mode would make " + std::to_string(triangles) + " triangles (" + mib +
                  " MiB of objects before any structure), more than the budget of 4194304; raise it with "
                  "--bsp-max-triangles (import_options.bsp_max_triangles in an experiment)");
    // A budget below a small map refuses it; raised to the map's count, it imports.
    TinyBsp three;
    three.lump[10] = m.lump[10];
    for (int s = 0; s < 3; ++s) three.surface(2, 0, 100 * 100, 0, 0, 100, 100);
    EXPECT_NE(error_of([&] {
                  parse_bsp(three.bytes(), "three.bsp", "triangles", nullptr, 3 * 19602 - 1);
              }).find("more than the budget of 58805"),
              std::string::npos);
    EXPECT_EQ(parse_bsp(three.bytes(), "three.bsp", "triangles", nullptr, 3 * 19602).size(), 3u * 19602);
    // Brushes mode makes no triangles: the budget does not apply.
    EXPECT_NO_THROW(parse_bsp(tiny_map().bytes(), "tiny.bsp", "brushes", nullptr, 1));
    // The option from experiment files: a whole number in range, recorded only when not the default.
    EXPECT_EQ(import_options_from_json({{"bsp_max_triangles", 100}}, "o").bsp_max_triangles, 100u);
    EXPECT_EQ(to_json(import_options_from_json({{"bsp_max_triangles", 100}}, "o"))["bsp_max_triangles"], 100);
    EXPECT_FALSE(to_json(ImportOptions{}).contains("bsp_max_triangles"));
    for (const nlohmann::json& bad : {nlohmann::json(0), nlohmann::json(-5), nlohmann::json(1.5),
                                      nlohmann::json("many"), nlohmann::json(std::uint64_t(1) << 40)})
        EXPECT_NE(error_of([&] {
                      import_options_from_json({{"bsp_max_triangles", bad}}, "scenes[0].import_options");
                  }).find("scenes[0].import_options.bsp_max_triangles: expected a whole number from 1 to"),
                  std::string::npos)
            << bad.dump();
}

TEST(BspImport, TruncatedMapsAreRefusedInEveryModeNamingTheLump) {
    // Cut 40 bytes: only the surfaces lump (13) runs past the end, which brushes mode does not read.
    const Bytes whole = tiny_map().bytes();
    Bytes cut = whole;
    cut.resize(cut.size() - 40);
    for (const char* mode : {"brushes", "triangles"}) {
        const std::string e = error_of([&] { parse_bsp(cut, "cut.bsp", mode); });
        EXPECT_NE(e.find("cut.bsp: lump 13 (surfaces): offset"), std::string::npos) << mode << ": " << e;
        EXPECT_NE(e.find("runs past the end of the file (" + std::to_string(cut.size()) + " bytes): truncated"),
                  std::string::npos)
            << mode << ": " << e;
    }
    // Every cut after the header, in both modes.
    for (std::size_t size = 8 + 17 * 8; size < whole.size(); ++size)
        for (const char* mode : {"brushes", "triangles"}) {
            const Bytes part(whole.begin(), whole.begin() + std::ptrdiff_t(size));
            const std::string e = error_of([&] { parse_bsp(part, "cut.bsp", mode); });
            EXPECT_NE(e.find("runs past the end of the file"), std::string::npos) << size << ' ' << mode << ": " << e;
        }
}

TEST(BspImport, BrushesReferringToTheSameSidesOverAndOverAreRefused) {
    // 7000 brushes each claiming the same 10000 sides: 7e7 side visits from a 170 KB file.
    TinyBsp m;
    m.shader("textures/base/solid", 0x1);
    const std::int32_t p = m.plane(1, 0, 0, 1);
    for (int k = 0; k < 10000; ++k) put_i32(m.lump[9], p), put_i32(m.lump[9], 0);
    for (int b = 0; b < 7000; ++b) put_i32(m.lump[8], 0), put_i32(m.lump[8], 10000), put_i32(m.lump[8], 0);
    EXPECT_EQ(error_of([&] { parse_bsp(m.bytes(), "sides.bsp", "brushes"); }),
              "sides.bsp: lump 8 (brushes): the brushes refer to 70000000 brushsides in all (of 10000), more than the "
              "limit of "
              "67108864 (kMaxSceneObjects, scene.h)");
}

TEST(BspImport, CoordinatesBeyondTheLimitNameTheBrushOrSurface) {
    TinyBsp m;
    m.shader("textures/base/solid", 0x1);
    m.brush({0, 0, 0}, {1, 1, 1}, 0);
    m.brush({0, 0, 0}, {1e20f, 1, 1}, 0);
    EXPECT_EQ(error_of([&] { parse_bsp(m.bytes(), "far.bsp", "brushes"); }),
              "far.bsp: brush 1: uid 1: coordinate 1e+20 beyond ±1e+15 (the largest magnitude every structure handles "
              "exactly)");
    for (Vec3 p : {Vec3{0, 0, 0}, Vec3{1, 0, 0}, Vec3{0, -3e38f, 0}}) m.vertex(p);
    for (std::int32_t i : {0, 1, 2}) put_i32(m.lump[11], i);
    m.surface(1, 0, 3, 0, 3);
    EXPECT_NE(error_of([&] {
                  parse_bsp(m.bytes(), "far.bsp", "triangles");
              }).find("far.bsp: surface 0: uid 0: coordinate -3e+38 beyond ±1e+15"),
              std::string::npos);
}

TEST(BspImport, MapsLargerThanTheLimitAreRefusedBeforeReading) {
    const fs::path big = scratch("huge.bsp");
    { std::ofstream(big).put('I'); }
    fs::resize_file(big, kMaxMapBytes + 1);  // sparse: no disk space, no time
    EXPECT_EQ(error_of([&] { import_bsp(big.string(), {}); }),
              big.string() + ": 536870913 bytes, more than the limit of 536870912 for a map (kMaxMapBytes, bsp.h)");
    fs::remove(big);
}

TEST(ModelImport, DeepGltfNodeChainsAreRefusedBeforeAssimpRecurses) {
    // 20000 nested nodes (0.6 MB) overflowed the 8 MB stack inside Importer::ReadFile (SIGSEGV).
    const std::string deep = write_text(scratch("deep.gltf"), gltf_chain(20000));
    const std::string e = error_of([&] { import_model(deep, "instances"); });
    EXPECT_NE(
        e.find(
            "deep.gltf: glTF node 1000 is nested deeper than 1000 (kMaxModelNesting, nesting.h) through \"children\""),
        std::string::npos)
        << e;
    // At the limit: imported, with the 1000 translations composed.
    const std::string ok = write_text(scratch("ok.gltf"), gltf_chain(kMaxModelNesting));
    const std::vector<Object> objects = import_model(ok, "instances");
    ASSERT_EQ(objects.size(), 1u);
    EXPECT_EQ(objects[0].box, box(1000, 0, 0, 1001, 1, 0));
    // The same from a .glb (its JSON chunk is checked too).
    const std::string json = gltf_chain(20000);
    Bytes glb{'g', 'l', 'T', 'F'};
    put_i32(glb, 2), put_i32(glb, std::int32_t(20 + json.size()));
    put_i32(glb, std::int32_t(json.size())), put_i32(glb, 0x4E4F534A);
    glb.insert(glb.end(), json.begin(), json.end());
    EXPECT_NE(error_of([&] {
                  import_model(write_file(scratch("deep.glb"), glb), "instances");
              }).find("is nested deeper than 1000"),
              std::string::npos);
}

TEST(ModelImport, GltfCyclesAndSharedNodesAreRefused) {
    EXPECT_NE(error_of([&] {
                  import_model(write_text(scratch("self.gltf"), gltf_text(R"([{"children": [0], "mesh": 0}])")),
                               "instances");
              }).find("self.gltf: glTF node 0 is its own child (a cycle)"),
              std::string::npos);
    EXPECT_NE(error_of([&] {
                  import_model(write_text(scratch("loop.gltf"),
                                          gltf_text(R"([{"mesh": 0}, {"children": [2]}, {"children": [1]}])")),
                               "instances");
              }).find("loop.gltf: glTF node 1 is its own ancestor through \"children\" (a cycle)"),
              std::string::npos);
    // 40 levels of nodes listing the next one twice: assimp copies shared nodes, 2^40 of them
    // (it ran past a minute and 20 GB).
    std::string nodes = "[";
    for (int i = 0; i < 40; ++i)
        nodes += "{\"children\": [" + std::to_string(i + 1) + ", " + std::to_string(i + 1) + "]},";
    const std::string e = error_of(
        [&] { import_model(write_text(scratch("shared.gltf"), gltf_text(nodes + R"({"mesh": 0}])")), "instances"); });
    EXPECT_NE(e.find("shared.gltf: glTF node 1 is listed twice among the children of node 0 (glTF node hierarchies are "
                     "strict trees)"),
              std::string::npos)
        << e;
    const std::string two = error_of([&] {
        import_model(write_text(scratch("two.gltf"),
                                gltf_text(R"([{"children": [2]}, {"children": [2]}, {"mesh": 0}])", "[0, 1]")),
                     "instances");
    });
    EXPECT_NE(
        two.find("two.gltf: glTF node 2 is a child of both node 0 and node 1 (glTF node hierarchies are strict trees)"),
        std::string::npos)
        << two;
    // A deep subtree listed as a scene root over and over is copied as often.
    std::string roots = "[";
    for (int i = 0; i < 70000; ++i) roots += "0,";
    std::string chain = "[";
    for (int i = 0; i < 999; ++i) chain += "{\"children\": [" + std::to_string(i + 1) + "]},";
    const std::string r = error_of([&] {
        import_model(write_text(scratch("roots.gltf"), gltf_text(chain + R"({"mesh": 0}])", roots + "0]")),
                     "instances");
    });
    EXPECT_NE(
        r.find(
            "roots.gltf: the glTF scenes list node subtrees of 70001000 nodes in all, more than the limit of 67108864"),
        std::string::npos)
        << r;
}

TEST(ModelImport, DeepJsonAndBracketsAreRefused) {
    const std::string deep_json = std::string(100000, '[') + std::string(100000, ']');
    const std::string e = error_of([&] {
        import_model(write_text(scratch("extras.gltf"), gltf_text("[{\"mesh\": 0}]", "[0]", deep_json)), "instances");
    });
    EXPECT_NE(
        e.find("extras.gltf: JSON arrays and objects nested deeper than 1000 (kMaxModelNesting, nesting.h) at byte "),
        std::string::npos)
        << e;
    // Brackets inside strings do not count.
    EXPECT_EQ(import_model(write_text(scratch("strings.gltf"),
                                      gltf_text("[{\"mesh\": 0, \"name\": \"" + std::string(5000, '[') + "\"}]")),
                           "instances")
                  .size(),
              1u);
    // DirectX .x nests frames in braces; assimp's parser recursed into a SIGSEGV at 100000 levels.
    std::string x = "xof 0303txt 0032\n";
    for (int i = 0; i < 100000; ++i) x += "Frame f {\n";
    for (int i = 0; i < 100000; ++i) x += "}\n";
    const std::string xe = error_of([&] { import_model(write_text(scratch("deep.x"), x), "instances"); });
    EXPECT_NE(xe.find("deep.x: brackets ({ } or [ ]) nested deeper than 1000 (kMaxModelNesting, nesting.h) at byte "
                      "10025, line 1002"),
              std::string::npos)
        << xe;
}

TEST(ModelImport, DeepColladaAndInstanceCyclesAreRefused) {
    // 8000 nested <node> elements: SIGSEGV inside ReadFile.
    const std::string e =
        error_of([&] { import_model(write_text(scratch("deep.dae"), collada_chain(8000)), "instances"); });
    EXPECT_NE(e.find("deep.dae: XML elements nested deeper than 1000 (kMaxModelNesting, nesting.h) at byte "),
              std::string::npos)
        << e;
    const std::vector<Object> ok = import_model(write_text(scratch("ok.dae"), collada_chain(990)), "instances");
    ASSERT_EQ(ok.size(), 1u);
    EXPECT_EQ(ok[0].box, box(990, 0, 0, 991, 1, 0));
    // <instance_node> a -> b -> a: assimp recursed without end (SIGSEGV).
    const std::string cycle =
        collada_text(R"(<node id="r"><instance_node url="#a"/></node>)",
                     R"(<library_nodes><node id="a"><instance_node url="#b"/></node>)"
                     R"(<node id="b"><instance_node url="#a"/><instance_geometry url="#g"/></node></library_nodes>)");
    const std::string c = error_of([&] { import_model(write_text(scratch("cycle.dae"), cycle), "instances"); });
    EXPECT_NE(c.find("cycle.dae: COLLADA node 'a' at byte "), std::string::npos) << c;
    EXPECT_NE(c.find("contains itself through <instance_node> (a cycle)"), std::string::npos) << c;
    // 40 levels each instancing the next twice: 2^40 copies (past a minute and 20 GB).
    std::string library = "<library_nodes>";
    for (int i = 0; i < 40; ++i)
        library += "<node id=\"n" + std::to_string(i) + "\"><instance_node url=\"#n" + std::to_string(i + 1) +
                   "\"/><instance_node url=\"#n" + std::to_string(i + 1) + "\"/></node>";
    library += R"(<node id="n40"><instance_geometry url="#g"/></node></library_nodes>)";
    const std::string x = error_of([&] {
        import_model(write_text(scratch("twice.dae"),
                                collada_text(R"(<node id="r"><instance_node url="#n0"/></node>)", library)),
                     "instances");
    });
    EXPECT_NE(x.find("twice.dae: the COLLADA node graph expands to more than 67108864 nodes through <instance_node>"),
              std::string::npos)
        << x;
    // Instances deeper than the limit in all, though no element is.
    std::string chain = "<library_nodes>";
    for (int i = 0; i < 1200; ++i)
        chain +=
            "<node id=\"c" + std::to_string(i) + "\"><instance_node url=\"#c" + std::to_string(i + 1) + "\"/></node>";
    chain += R"(<node id="c1200"><instance_geometry url="#g"/></node></library_nodes>)";
    const std::string d = error_of([&] {
        import_model(
            write_text(scratch("long.dae"), collada_text(R"(<node id="r"><instance_node url="#c0"/></node>)", chain)),
            "instances");
    });
    EXPECT_NE(d.find("expands to a hierarchy deeper than 1000"), std::string::npos) << d;
}

TEST(ModelImport, AssimpRunsOnItsOwnLargeStack) {
    // 990 COLLADA levels are within the limit but take assimp about 1.2 MB of stack: a caller on
    // a 512 KB stack (a thread, or deep in its own work) must still get the model.
    const std::string dae = write_text(scratch("stack.dae"), collada_chain(990));
    const std::string gltf = write_text(scratch("stack.gltf"), gltf_chain(kMaxModelNesting));
    std::size_t n = 0;
    on_small_stack(512 << 10,
                   [&] { n = import_model(dae, "triangles").size() + import_model(gltf, "triangles").size(); });
    EXPECT_EQ(n, 2u);
}

TEST(ModelImport, ObjectCountsAreLimitedBeforeAllocating) {
    // One mesh of 70000 triangles (indices 0 1 2 over and over) under 1000 nodes: 7e7 triangles.
    std::string indices;
    for (int i = 0; i < 70000; ++i) indices += std::string("\0\0\1\0\2\0", 6);
    std::string b64;
    static const char* t = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const std::string positions("\0\0\0\0\0\0\0\0\0\0\0\0\0\0\x80\x3f\0\0\0\0\0\0\0\0\0\0\0\0\0\0\x80\x3f\0\0\0\0", 36);
    const std::string buffer = positions + indices;
    for (std::size_t i = 0; i < buffer.size(); i += 3) {
        std::uint32_t v = std::uint32_t(std::uint8_t(buffer[i])) << 16;
        if (i + 1 < buffer.size()) v |= std::uint32_t(std::uint8_t(buffer[i + 1])) << 8;
        if (i + 2 < buffer.size()) v |= std::uint8_t(buffer[i + 2]);
        b64 += t[(v >> 18) & 63], b64 += t[(v >> 12) & 63];
        b64 += i + 1 < buffer.size() ? t[(v >> 6) & 63] : '=';
        b64 += i + 2 < buffer.size() ? t[v & 63] : '=';
    }
    std::string nodes = R"([{"children": [)";
    for (int i = 1; i <= 1000; ++i) nodes += std::to_string(i) + (i < 1000 ? "," : "]}");
    for (int i = 1; i <= 1000; ++i) nodes += R"(, {"mesh": 0})";
    const std::string gltf = R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": )" +
                             nodes + R"(],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
                    {"bufferView": 1, "componentType": 5123, "count": 210000, "type": "SCALAR"}],
      "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 420000}],
      "buffers": [{"byteLength": 420036, "uri": "data:application/octet-stream;base64,)" +
                             b64 + R"("}]})";
    const std::string path = write_text(scratch("many.gltf"), gltf);
    EXPECT_EQ(error_of([&] { import_model(path, "triangles"); }),
              path +
                  ": triangles mode would make 70000000 objects, more than the limit of 67108864 per scene "
                  "(kMaxSceneObjects, scene.h); "
                  "try --model-mode instances");
    EXPECT_EQ(import_model(path, "instances").size(), 1000u);
}

TEST(ModelImport, CoordinatesBeyondTheLimitNameTheNode) {
    const std::string obj = write_text(scratch("far.obj"), "o far\nv 0 0 0\nv 1e20 0 0\nv 0 1 0\nf 1 2 3\n");
    const std::string e = error_of([&] { import_model(obj, "instances"); });
    EXPECT_NE(e.find("far.obj: node 'far': uid 0: coordinate 1e+20 beyond ±1e+15"), std::string::npos) << e;
}

TEST(SceneImport, CliRefusesACsvBoxBeyondTheCoordinateLimit) {
    // `200,0,40,0,1e20,41,1` among 200 unit boxes: simulate --structure embree aborted on this.
    std::string csv = "uid,minx,miny,minz,maxx,maxy,maxz\n";
    for (int i = 0; i < 200; ++i)
        csv += std::to_string(i) + "," + std::to_string(2 * (i % 10)) + ",0,0," + std::to_string(2 * (i % 10) + 1) +
               ",1,1\n";
    const std::string in = write_text(scratch("giant.csv"), csv + "200,0,40,0,1e20,41,1\n");
    const std::string out = scratch("giant.rcbscene").string(), err = scratch("giant.err").string();
    fs::remove(out);
    const int rc =
        std::system((std::string(RCBENCH_BINARY) + " scene import " + in + " -o " + out + " 2> " + err).c_str());
    EXPECT_EQ(WEXITSTATUS(rc), 2);
    EXPECT_FALSE(fs::exists(out));
    std::ifstream e(err);
    std::string line, more;
    std::getline(e, line);
    EXPECT_FALSE(std::getline(e, more)) << more;
    EXPECT_NE(line.find("giant.csv:202: uid 200: field 5 (maxx): coordinate '1e20' beyond ±1e+15"), std::string::npos)
        << line;
}

/// The real OpenArena maps (scripts/fetch_maps.sh); skipped when they have not been fetched.
TEST(BspImport, RealOpenArenaMapsMatchGroundTruthInEveryStructure) {
    const fs::path pk3 = fs::path(RCBENCH_SOURCE_DIR) / "data/maps/pak1-maps.pk3";
    RCB_REQUIRE_REAL_DATA(fs::exists(pk3), "no " << pk3 << " (run scripts/fetch_maps.sh to fetch the OpenArena maps)");
    for (const char* map : {"oa_dm1", "aggressor"})
        for (const char* mode : {"brushes", "triangles"}) {
            BspSummary s;
            std::vector<Object> objects = import_bsp(pk3.string(), {mode, map}, &s);
            ASSERT_GT(objects.size(), 100u) << map << " " << mode;
            for (const Object& o : objects)
                ASSERT_TRUE(is_finite(o.box.min) && is_finite(o.box.max) && !o.box.is_empty());
            RaySettings rays;
            rays.per_frame = 300;
            rays.mix = parse_ray_mix("center:0.5,los:0.25,ground:0.25");
            const Recording r =
                add_dynamics(std::move(objects), DynamicsSettings{}, rays, 3, 7, nlohmann::json::object());
            const std::string name = std::string(map) + "-" + mode;
            for (const char* structure : {"bf", "hg", "lbvh", "embree", "bullet_dbvt"})
                test::expect_matches_ground_truth(r, structure, nlohmann::json::object(), name);
        }
}

TEST(ModelImport, RealAssimpTestModelImports) {
    const fs::path glb =
        fs::path(RCBENCH_SOURCE_DIR) / "data/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
    RCB_REQUIRE_REAL_DATA(fs::exists(glb),
                          "no " << glb << " (run scripts/fetch_maps.sh to fetch assimp's test models)");
    ModelSummary s;
    const std::vector<Object> instances = import_model(glb.string(), "instances", &s);
    EXPECT_EQ(instances.size(), s.instances);
    EXPECT_GT(instances.size(), 50u);
    const std::vector<Object> triangles = import_model(glb.string(), "triangles");
    EXPECT_GT(triangles.size(), instances.size());
    RaySettings rays;
    rays.per_frame = 300;
    const Recording r = add_dynamics(instances, DynamicsSettings{}, rays, 2, 3, nlohmann::json::object());
    for (const char* structure : {"hg", "embree", "bullet_dbvt"})
        test::expect_matches_ground_truth(r, structure, {}, "2CylinderEngine");
}

}  // namespace rcb
