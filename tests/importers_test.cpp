// Importers: Quake III / OpenArena BSP (a tiny map built here, byte by byte; pk3 as a stored zip
// built here), assimp models (a tiny OBJ and glTF written here), the dispatch by extension, the
// CLI, and the real OpenArena maps when scripts/fetch_maps.sh has fetched them.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <functional>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "core/error.h"
#include "core/generators.h"
#include "core/importers/bsp.h"
#include "core/importers/model.h"
#include "core/importers/scene_import.h"
#include "runner/experiment.h"
#include "tests/test_scenes.h"

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
        put_i32(b, -1);                              // color
    }
    void surface(std::int32_t type, std::int32_t first_vert, std::int32_t num_verts, std::int32_t first_index,
                 std::int32_t num_indexes, std::int32_t pw = 0, std::int32_t ph = 0) {
        Bytes& b = lump[13];
        for (std::int32_t v : {0, -1, type, first_vert, num_verts, first_index, num_indexes, 0, 0, 0, 0, 0}) put_i32(b, v);
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
std::string write_text(const fs::path& path, const std::string& text) { return write_file(path, Bytes(text.begin(), text.end())); }

fs::path scratch(const std::string& name) {
    const fs::path dir = fs::temp_directory_path() / ("rcb_importers_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    return dir / name;
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

std::string error_of(const std::function<void()>& f) {
    try {
        f();
    } catch (const InputError& e) {
        return e.what();
    }
    return "(no InputError)";
}

Aabb box(float x0, float y0, float z0, float x1, float y1, float z1) { return {{x0, y0, z0}, {x1, y1, z1}}; }

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
    for (std::size_t i = 0; i < objects.size(); ++i) EXPECT_EQ(objects[i].uid, i);
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
    EXPECT_NE(error_of([&] { parse_bsp(Bytes(200, 'x'), "junk.bsp", "brushes"); }).find("junk.bsp: header: magic 'xxxx'"),
              std::string::npos);

    TinyBsp odd = tiny_map();
    odd.lump[8].push_back(0);
    EXPECT_EQ(error_of([&] { parse_bsp(odd.bytes(), "odd.bsp", "brushes"); }),
              "odd.bsp: lump 8 (brushes): length 49 is not a multiple of 12");

    TinyBsp bad = tiny_map();
    std::int32_t big = 1000;
    std::memcpy(bad.lump[8].data() + 4, &big, 4);  // brush 0 claims 1000 sides
    const std::string sides = error_of([&] { parse_bsp(bad.bytes(), "bad.bsp", "brushes"); });
    EXPECT_NE(sides.find("bad.bsp: lump 8 (brushes): brush 0 refers to brushsides 0..999 beyond the"), std::string::npos) << sides;

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
    const std::string one = write_file(scratch("one.pk3"), stored_zip({{"readme.txt", Bytes{'h', 'i'}}, {"maps/tiny.bsp", map}}));
    const std::string two = write_file(scratch("two.pk3"), stored_zip({{"maps/a.bsp", map}, {"maps/b.bsp", other.bytes()}}));
    EXPECT_EQ(pk3_maps(two), (std::vector<std::string>{"maps/a.bsp", "maps/b.bsp"}));
    EXPECT_EQ(import_bsp(one, {}).size(), 2u);
    EXPECT_EQ(import_bsp(two, {"brushes", "b"}).size(), 3u);
    EXPECT_EQ(import_bsp(two, {"brushes", "maps/a.bsp"}).size(), 2u);
    EXPECT_EQ(import_bsp(two, {"triangles", "a"}).size(), 10u);
    EXPECT_NE(error_of([&] { import_bsp(two, {}); }).find("holds 2 maps, choose one with --map (a, b)"), std::string::npos);
    EXPECT_NE(error_of([&] { import_bsp(two, {"brushes", "c"}); }).find("no map 'c' inside (maps: a, b)"), std::string::npos);
    const std::string junk = write_text(scratch("junk.pk3"), "not a zip at all");
    EXPECT_NE(error_of([&] { import_bsp(junk, {}); }).find("junk.pk3: not a readable zip"), std::string::npos);
    // A broken map inside a pk3 names the pk3, the entry and the lump.
    TinyBsp odd = tiny_map();
    odd.lump[2].push_back(0);
    const std::string bad = write_file(scratch("bad.pk3"), stored_zip({{"maps/odd.bsp", odd.bytes()}}));
    EXPECT_EQ(error_of([&] { import_bsp(bad, {}); }), "bad.pk3:maps/odd.bsp: lump 2 (planes): length 417 is not a multiple of 16");
}

TEST(ModelImport, ObjInstancesAndTriangles) {
    const std::string obj = write_text(scratch("two.obj"),
                                       "o quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"
                                       "o tri\nv 2 2 2\nv 3 2 2\nv 2 3 4\nf 5 6 7\n");
    ModelSummary s;
    std::vector<Object> instances = import_model(obj, "instances", &s);
    ASSERT_EQ(instances.size(), 2u);
    std::sort(instances.begin(), instances.end(), [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    EXPECT_EQ(instances[0].box, box(0, 0, 0, 1, 1, 0));
    EXPECT_EQ(instances[1].box, box(2, 2, 2, 3, 3, 4));
    const std::vector<Object> triangles = import_model(obj, "triangles", &s);
    EXPECT_EQ(triangles.size(), 3u);  // the quad triangulated, and the triangle
    EXPECT_EQ(s.triangles, 3u);
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
    std::sort(objects.begin(), objects.end(), [](const Object& a, const Object& b) { return a.box.min.x < b.box.min.x; });
    EXPECT_EQ(objects[0].box, box(0, 0, 5, 2, 2, 5));
    EXPECT_EQ(objects[1].box, box(10, 0, 0, 11, 1, 0));
    EXPECT_EQ(import_model(path, "triangles").size(), 2u);
}

TEST(ModelImport, ErrorsNameTheFile) {
    const std::string junk = write_text(scratch("junk.glb"), "glTF but not really");
    const std::string e = error_of([&] { import_model(junk, "instances"); });
    EXPECT_NE(e.find("junk.glb: assimp: "), std::string::npos) << e;
    EXPECT_NE(error_of([&] { import_model(junk, "points"); }).find("expected instances or triangles"), std::string::npos);
}

TEST(SceneImport, DispatchesByExtensionAndValidatesOptions) {
    EXPECT_EQ(importer_for("a.csv"), "csv");
    EXPECT_EQ(importer_for("maps/q3dm1.BSP"), "bsp");
    EXPECT_EQ(importer_for("x.pk3"), "bsp");
    EXPECT_EQ(importer_for("ship.glb"), "model");
    EXPECT_EQ(importer_for("ship.obj"), "model");
    EXPECT_NE(error_of([] { importer_for("notes.txt2"); }).find("notes.txt2: cannot import '.txt2' files"), std::string::npos);
    EXPECT_THROW(import_options_from_json({{"mode", "brushes"}}, "scenes[0].import_options"), InputError);
    EXPECT_THROW(import_options_from_json({{"bsp_mode", "faces"}}, "scenes[0].import_options"), InputError);
    EXPECT_EQ(import_options_from_json({{"bsp_mode", "triangles"}, {"map", "oa_dm1"}}, "x").map, "oa_dm1");
    const std::string bsp = write_file(scratch("tiny.bsp"), tiny_map().bytes());
    nlohmann::json meta;
    EXPECT_EQ(import_objects(bsp, {}, &meta).size(), 2u);
    EXPECT_EQ(meta["importer"], "bsp");
    EXPECT_EQ(meta["brushes"]["skipped_non_solid"], 1);
}

TEST(SceneImport, CliImportsMapsAndModelsAndExitsTwoOnBadFiles) {
    const std::string bsp = write_file(scratch("cli.bsp"), tiny_map().bytes());
    const std::string out = scratch("cli.rcbscene").string();
    const std::string bin = RCBENCH_BINARY;
    EXPECT_EQ(std::system((bin + " scene import " + bsp + " -o " + out + " --frames 2 --rays 10 --bsp-mode triangles > /dev/null").c_str()), 0);
    EXPECT_TRUE(fs::exists(out));
    const std::string obj = write_text(scratch("cli.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    EXPECT_EQ(std::system((bin + " scene import " + obj + " -o " + out + " --frames 1 --model-mode triangles > /dev/null").c_str()), 0);
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
            parse_experiment(R"({"name": "t", "scenes": [)" + scene + R"(], "structures": [{"name": "bf"}]})", "t.json", base);
        });
    };
    EXPECT_NE(bad(R"({"import": "tiny.bsp", "import_options": {"mode": "x"}})").find("scenes[0].import_options"), std::string::npos);
    EXPECT_NE(bad(R"({"import": "tiny.bsp", "import_options": {"bsp_mode": "faces"}})").find("bsp_mode"), std::string::npos);
    EXPECT_NE(bad(R"({"preset": "uni-s", "import_options": {}})").find("only an \"import\" scene takes import options"), std::string::npos);
}

/// The real OpenArena maps (scripts/fetch_maps.sh); skipped when they have not been fetched.
TEST(BspImport, RealOpenArenaMapsMatchGroundTruthInEveryStructure) {
    const fs::path pk3 = fs::path(RCBENCH_SOURCE_DIR) / "data/maps/pak1-maps.pk3";
    if (!fs::exists(pk3)) GTEST_SKIP() << "no " << pk3 << " (run scripts/fetch_maps.sh to fetch the OpenArena maps)";
    for (const char* map : {"oa_dm1", "aggressor"})
        for (const char* mode : {"brushes", "triangles"}) {
            BspSummary s;
            std::vector<Object> objects = import_bsp(pk3.string(), {mode, map}, &s);
            ASSERT_GT(objects.size(), 100u) << map << " " << mode;
            for (const Object& o : objects) ASSERT_TRUE(is_finite(o.box.min) && is_finite(o.box.max) && !o.box.is_empty());
            RaySettings rays;
            rays.per_frame = 300;
            rays.mix = parse_ray_mix("center:0.5,los:0.25,ground:0.25");
            const Recording r = add_dynamics(std::move(objects), DynamicsSettings{}, rays, 3, 7, nlohmann::json::object());
            const std::string name = std::string(map) + "-" + mode;
            for (const char* structure : {"bf", "hg", "lbvh", "embree", "bullet_dbvt"})
                test::expect_matches_ground_truth(r, structure, nlohmann::json::object(), name);
        }
}

TEST(ModelImport, RealAssimpTestModelImports) {
    const fs::path glb = fs::path(RCBENCH_SOURCE_DIR) / "data/models/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb";
    if (!fs::exists(glb)) GTEST_SKIP() << "no " << glb << " (run scripts/fetch_maps.sh to fetch assimp's test models)";
    ModelSummary s;
    const std::vector<Object> instances = import_model(glb.string(), "instances", &s);
    EXPECT_EQ(instances.size(), s.instances);
    EXPECT_GT(instances.size(), 50u);
    const std::vector<Object> triangles = import_model(glb.string(), "triangles");
    EXPECT_GT(triangles.size(), instances.size());
    RaySettings rays;
    rays.per_frame = 300;
    const Recording r = add_dynamics(instances, DynamicsSettings{}, rays, 2, 3, nlohmann::json::object());
    for (const char* structure : {"hg", "embree", "bullet_dbvt"}) test::expect_matches_ground_truth(r, structure, {}, "2CylinderEngine");
}

}  // namespace rcb
