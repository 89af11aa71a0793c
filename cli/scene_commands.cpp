// rcbench scene gen | import | info | features | maps
#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>

#include "core/scene/import/csv.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/generate/physics.h"
#include "core/scene/generate/stream.h"
#include "core/scene/import/broadmark.h"
#include "core/scene/phases.h"
#include "core/scene/import/bsp.h"
#include "core/scene/import/scene_import.h"
#include "core/base/json_input.h"
#include "core/base/output_file.h"
#include "core/base/statistics.h"
#include "core/scene/recording_io.h"
#include "core/scene/workload.h"
#include "sim/scene_features.h"
#include "cli/cli_checks.h"
#include "cli/commands.h"
#include "cli/table.h"

namespace rcb {
namespace {

/// Options shared by `gen` and `import`: how the scene moves and which rays it casts.
struct DynamicsOptions {
    std::uint32_t frames = 10;
    std::uint64_t seed = 1;
    std::uint32_t rays = 1000;
    std::string ray_mix = "center";
    std::string query_mix = "all";
    std::string queries;  ///< a query preset, instead of --ray-mix and --query-mix
    DynamicsSettings dynamics;
};

void add_dynamics_options(CLI::App& cmd, DynamicsOptions& o) {
    cmd.add_option("--frames", o.frames, "Frames after frame 0")
        ->capture_default_str()
        ->check(whole_number(0, 1'000'000));
    cmd.add_option("--seed", o.seed, "Seed of every random choice (recorded in the file)")
        ->capture_default_str()
        ->check(whole_number());
    cmd.add_option("--rays", o.rays, "Rays per frame")->capture_default_str()->check(whole_number(0, 100'000'000));
    CLI::Option* ray_mix =
        cmd.add_option("--ray-mix", o.ray_mix,
                       "Ray modes with weights, of " + join(ray_mode_names()) + " (e.g. center:0.7,los:0.3)")
            ->capture_default_str();
    CLI::Option* query_mix =
        cmd.add_option("--query-mix", o.query_mix,
                       "Query kinds with weights, of all, closest, any (e.g. closest:0.6,any:0.3,all:0.1), drawn per "
                       "ray from the seed's own stream; only all keeps the file's older format")
            ->capture_default_str();
    cmd.add_option("--queries", o.queries,
                   "A game query preset instead of --ray-mix and --query-mix, each ray mode with its own kind: shots "
                   "(fire rays from agents, closest hit), visibility (sight lines between agents, any hit), sensors "
                   "(short sensor rays around agents, all hits), game (our blend: 50% shots, 30% visibility, 20% "
                   "sensors); agents are random live objects (docs/recording-format.md, Query presets)")
        ->check(CLI::IsMember(query_preset_names()))
        ->excludes(ray_mix)
        ->excludes(query_mix);
    cmd.add_option("--change-fraction", o.dynamics.change_fraction, "Objects changed per frame, as a fraction")
        ->capture_default_str()
        ->check(finite_range(0.0, 1.0));
    cmd.add_option("--insert-share", o.dynamics.insert_share, "Share of the changes that are inserts")
        ->capture_default_str()
        ->check(finite_range(0.0, 1.0));
    cmd.add_option("--remove-share", o.dynamics.remove_share, "Share of the changes that are removes (the rest move)")
        ->capture_default_str()
        ->check(finite_range(0.0, 1.0));
    cmd.add_option("--move-scale", o.dynamics.move_scale,
                   "A move shifts each axis by up to this x the object's longest edge")
        ->capture_default_str()
        ->check(finite_range(0.0, 1000.0));
}

RaySettings ray_settings(const DynamicsOptions& o) {
    if (o.dynamics.insert_share + o.dynamics.remove_share > 1.0)
        throw InputError("--insert-share plus --remove-share must not exceed 1");
    RaySettings r;
    r.per_frame = o.rays;
    r.mix = parse_ray_mix(o.ray_mix);
    try {
        r.query_mix = parse_query_mix(o.query_mix);
    } catch (const InputError& e) {
        throw InputError(std::string("--query-mix: ") + e.what());
    }
    if (!o.queries.empty()) r = with_query_preset(r, o.queries);
    return r;
}

void print_written(const Recording& r, const std::string& path) {
    std::size_t rays = 0;
    for (const Frame& f : r.frames) rays += f.rays.size();
    std::cout << "wrote " << path << ": " << r.initial.size() << " objects, " << r.frames.size() << " frames, " << rays
              << " rays\n";
}

std::string shares_text(const nlohmann::json& list) {
    std::string out;
    for (const auto& v : list) out += (out.empty() ? "" : " ") + fixed(100 * v.get<double>(), 1) + "%";
    return out.empty() ? "none" : out;
}

/// The format version in a recording's header (read_recording has checked the file already).
std::uint32_t file_version(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    unsigned char header[12] = {};
    in.read(reinterpret_cast<char*>(header), sizeof header);
    return std::uint32_t(header[8]) | std::uint32_t(header[9]) << 8 | std::uint32_t(header[10]) << 16 |
           std::uint32_t(header[11]) << 24;
}

void scene_info(const std::string& path, bool as_json) {
    const Recording r = read_recording(path);
    const std::uint32_t version = file_version(path);
    // Objects per shape kind: frame 0's, and those inserted or moved later (a move may not change
    // an object's kind in generated scenes, but a recording is free to).
    std::array<std::size_t, kShapeKinds> initial_kinds{}, later_kinds{};
    for (const Object& o : r.initial) ++initial_kinds[int(o.shape.kind)];
    for (const Frame& f : r.frames)
        for (const auto* list : {&f.inserts, &f.moves})
            for (const Object& o : *list) ++later_kinds[int(o.shape.kind)];
    nlohmann::json kinds = nlohmann::json::object(), later = nlohmann::json::object();
    std::string kinds_text, later_text;
    for (int k = 0; k < kShapeKinds; ++k) {
        const std::string name(shape_name(ShapeKind(k)));
        kinds[name] = initial_kinds[k];
        later[name] = later_kinds[k];
        if (initial_kinds[k])
            kinds_text += (kinds_text.empty() ? "" : ", ") + name + " " + std::to_string(initial_kinds[k]);
        if (later_kinds[k])
            later_text += (later_text.empty() ? "" : ", ") + name + " " + std::to_string(later_kinds[k]);
    }
    const Aabb bounds = bounds_of(r.initial);
    std::vector<double> edges;
    edges.reserve(r.initial.size());
    for (const Object& o : r.initial) edges.push_back(o.box.longest_edge());
    std::sort(edges.begin(), edges.end());
    const auto q = [&](double p) { return edges.empty() ? 0.0 : quantile(edges, p); };
    const SceneWorkload w = scene_workload(r);
    const std::array<std::size_t, kQueryKinds>& query_kinds = w.rays_by_kind;
    const nlohmann::json wj = w.to_json();
    nlohmann::json size = {{"min", edges.empty() ? 0 : edges.front()},
                           {"p10", q(0.1)},
                           {"median", q(0.5)},
                           {"p90", q(0.9)},
                           {"max", edges.empty() ? 0 : edges.back()}};
    const nlohmann::json meta = parse_json_document(r.meta, path + ": META");
    nlohmann::json j = {
        {"file", path},
        {"version", version},
        {"objects", r.initial.size()},
        {"shapes", kinds},
        {"changed_shapes", later},
        {"frames", r.frames.size()},
        {"rays", w.rays()},
        {"rays_per_frame", w.rays_per_frame},
        {"query_kinds", wj["query_kinds"]},
        {"query_shares", wj["query_shares"]},
        {"changes_per_frame", w.changes_per_frame},
        {"inserts", w.inserts},
        {"removes", w.removes},
        {"moves", w.moves},
        {"bounds",
         {{"min", {bounds.min.x, bounds.min.y, bounds.min.z}}, {"max", {bounds.max.x, bounds.max.y, bounds.max.z}}}},
        {"longest_edge", size},
        {"motion", wj["motion"]},
        {"meta", meta}};
    std::string phases_text;
    for (const MotionPhase& p : motion_phases(r)) {
        j["motion"]["phases"].push_back({{"name", p.name},
                                         {"first", p.first},
                                         {"last", p.last},
                                         {"frames", p.frames()},
                                         {"moving_share", p.moving_share}});
        phases_text += (phases_text.empty() ? "" : ", ") + p.name + " " +
                       (p.empty() ? "none"
                                  : std::to_string(p.first) + "-" + std::to_string(p.last) + " " +
                                        fixed(100 * p.moving_share, 1) + "%");
    }
    if (as_json) {
        std::cout << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << '\n';
        return;
    }
    std::cout << path << '\n';
    TextTable t({"", ""});  // label, value
    t.add({"format version", std::to_string(version)});
    t.add({"objects (frame 0)", std::to_string(r.initial.size())});
    t.add({"shapes (frame 0)", kinds_text.empty() ? "none" : kinds_text});
    if (!later_text.empty()) t.add({"shapes inserted or moved", later_text});
    t.add({"frames", std::to_string(r.frames.size())});
    t.add({"rays per frame", fixed(w.rays_per_frame, 1)});
    t.add({"query kinds (all rays)", "all " + std::to_string(query_kinds[0]) + ", closest " +
                                         std::to_string(query_kinds[1]) + ", any " + std::to_string(query_kinds[2])});
    if (meta.contains("rays") && meta["rays"].is_object() && meta["rays"].contains("queries"))
        t.add({"query preset", json_excerpt(meta["rays"]["queries"]) + " (" + w.kinds_text() + ")"});
    t.add({"changes per frame", fixed(w.changes_per_frame, 1) + " (inserts " + std::to_string(w.inserts) +
                                    ", removes " + std::to_string(w.removes) + ", moves " + std::to_string(w.moves) +
                                    " in all)"});
    t.add({"bounds min", fixed(bounds.min.x, 3) + ", " + fixed(bounds.min.y, 3) + ", " + fixed(bounds.min.z, 3)});
    t.add({"bounds max", fixed(bounds.max.x, 3) + ", " + fixed(bounds.max.y, 3) + ", " + fixed(bounds.max.z, 3)});
    t.add({"longest edge min / p10 / median / p90 / max", fixed(size["min"], 3) + " / " + fixed(size["p10"], 3) +
                                                              " / " + fixed(size["median"], 3) + " / " +
                                                              fixed(size["p90"], 3) + " / " + fixed(size["max"], 3)});
    if (!edges.empty() && edges.front() > 0) t.add({"size span (max / min)", fixed(edges.back() / edges.front(), 1)});
    const nlohmann::json& m = j["motion"];
    t.add({"changed per frame p10 / p50 / p90", fixed(100 * m["changed_share"]["p10"].get<double>(), 1) + "% / " +
                                                    fixed(100 * m["changed_share"]["p50"].get<double>(), 1) + "% / " +
                                                    fixed(100 * m["changed_share"]["p90"].get<double>(), 1) + "%"});
    t.add({"changed per frame, first / last frames",
           shares_text(m["first_frames"]) + " / " + shares_text(m["last_frames"])});
    t.add({"moving per phase (frames, share)", phases_text});
    t.add({"move / longest edge median (p90)", fixed(m["move_over_size"]["median"].get<double>(), 4) + " (" +
                                                   fixed(m["move_over_size"]["p90"].get<double>(), 4) + ")"});
    t.print(std::cout);
    std::cout << "origin  " << json_excerpt(meta, 400) << '\n';
}

/// A sink that adds the map's description to the meta of the scene it passes on (`--on-map`).
class OnMapSink final : public SceneSink {
public:
    OnMapSink(SceneSink& next, nlohmann::json imported) : next_(next), imported_(std::move(imported)) {}
    void begin(const std::string& meta_text, const std::vector<Object>& initial) override {
        nlohmann::json meta = nlohmann::json::parse(meta_text);
        meta["on_map"] = imported_;
        next_.begin(meta.dump(), initial);
    }
    void frame(const Frame& frame) override { next_.frame(frame); }

private:
    SceneSink& next_;
    nlohmann::json imported_;
};

/// `scene gen --on-map`: the map's solid brushes in metres with y up (bsp_box_in_metres), then the
/// pile dropped onto them, streamed into `sink`; the recording's meta says which map and how it was
/// placed.
void pile_on_map(const SceneSettings& s, const std::string& file, const std::string& map, SceneSink& sink) {
    if (s.generator != "pile")
        throw InputError("--on-map: only --generator pile is dropped onto a map, not " + s.generator);
    if (importer_for(file) != "bsp")
        throw InputError("--on-map: " + file + ": expected a Quake III / OpenArena map (.bsp or .pk3)");
    ImportOptions options;
    options.map = map;
    nlohmann::json imported;
    std::vector<Aabb> boxes;
    for (const Object& o : import_objects(file, options, &imported)) boxes.push_back(bsp_box_in_metres(o.box));
    if (boxes.empty()) throw InputError("--on-map: " + file + ": no solid brushes");
    imported["metres_per_unit"] = kBspUnitMetres;
    imported["axes"] = "map z up as y, map y as -z";
    OnMapSink on_map(sink, imported);
    try {
        stream_physics_scene(s, on_map, boxes);
    } catch (const InputError& e) {
        throw InputError("--on-map: " + file + ": " + e.what());
    }
}

/// `scene gen`: a scene from a preset or a generator.
void add_gen_command(CLI::App& scene) {
    struct GenOptions {
        std::string preset;
        std::string generator;
        std::uint32_t objects = 0;
        std::string out;
        DynamicsOptions dyn;
        ShapeSettings shapes;
        double time_step = 0;  // the generator's default
        std::string shape_set;
        double fill = 0;
        std::string on_map, map;
    };
    auto gen = std::make_shared<GenOptions>();
    CLI::App* g = scene.add_subcommand("gen", "Generate a scene recording from a preset or a generator");
    g->add_option("--preset", gen->preset,
                  "Thesis scenes uni-s/m/l and irreg-s/m/l (99, 5104, 14021 objects), irreg-xl (1M); peer-comparison "
                  "scenes jittered-m/l and clusters-m/l (5104, 14021), clusters-xl (1M); failure modes <generator>-s/m "
                  "(1000, 10000 objects)")
        ->check(CLI::IsMember(preset_names()));
    g->add_option("--generator", gen->generator,
                  "Instead of a preset, with --objects. Physics generators (" + join(physics_generators()) +
                      ") are simulated by Bullet: every awake body moves each frame, sleeping ones do not; the "
                      "--change-fraction, --insert-share, --remove-share and --move-scale options do not apply to them")
        ->check(CLI::IsMember(scene_generators()));
    add_deprecated_alias(g, "--kind", "--generator", gen->generator)->check(CLI::IsMember(scene_generators()));
    g->add_option("--time-step", gen->time_step,
                  "Physics generators: seconds simulated per frame (default 1/60 in one Bullet step; Broadmark's "
                  "brownian, freefall and gravity 1/30 in 4 substeps, its generator's)")
        ->check(finite_range(1e-4, 0.1));
    g->add_option(
         "--shape-set", gen->shape_set,
         "Broadmark's generators (brownian, freefall, gravity): its object set, cubes (unit cubes), spheres "
         "(diameter 1) or assorted (cubes, bars and slabs of 38:1, planks up to 57:1, random boxes; default cubes)")
        ->check(CLI::IsMember(broadmark_shape_sets()));
    g->add_option("--fill", gen->fill,
                  "Broadmark's generators: share of the arena the objects' unit volumes fill, which sizes the arena "
                  "(default 0.1, its generator's ObjectDensity; its shipped wizard sets 0.01)")
        ->check(finite_range(1e-6, 0.5));
    g->add_option("--objects", gen->objects, "Object count (overrides the preset's)")
        ->check(whole_number(1, kMaxSceneObjects));
    g->add_option("-o,--output", gen->out, "Recording file to write")->required();
    g->add_option("--on-map", gen->on_map,
                  "Pile only: a Quake III / OpenArena map (.bsp, or .pk3 with maps/*.bsp) whose solid brushes, in "
                  "metres (a unit is 0.0254 m) with the map's z as y, become static boxes the bodies are dropped "
                  "onto, each from a random free 2 m cell above them; the recording holds the bodies (uids 0..N-1) "
                  "and then the map's boxes, which never move")
        ->check(input_file());
    g->add_option("--map", gen->map, "With --on-map, a .pk3 holding several maps: which one (NAME or maps/NAME.bsp)");
    add_dynamics_options(*g, gen->dyn);
    g->add_option("--rotated-share", gen->shapes.rotated_share,
                  "Share of the objects that become oriented boxes: the generated box's half extents, a random "
                  "rotation (their boxes grow to the bounds)")
        ->capture_default_str()
        ->check(finite_range(0.0, 1.0));
    g->add_option("--sphere-share", gen->shapes.sphere_share,
                  "Share of the objects that become spheres inscribed in the generated box")
        ->capture_default_str()
        ->check(finite_range(0.0, 1.0));
    g->add_option("--capsule-share", gen->shapes.capsule_share,
                  "Share of the objects that become capsules along the generated box's longest axis (the three "
                  "shares add up to at most 1)")
        ->capture_default_str()
        ->check(finite_range(0.0, 1.0));
    g->callback([gen] {
        SceneSettings s;
        if (!gen->preset.empty())
            s = preset_settings(gen->preset);
        else if (!gen->generator.empty())
            s.generator = gen->generator;
        else
            throw InputError("scene gen: give --preset or --generator");
        if (!gen->generator.empty()) s.generator = gen->generator;
        if (gen->objects)
            s.objects = gen->objects;
        else if (gen->preset.empty())
            throw InputError("scene gen: --generator needs --objects");
        s.seed = gen->dyn.seed;
        s.frames = gen->dyn.frames;
        s.dynamics = gen->dyn.dynamics;
        s.rays = ray_settings(gen->dyn);
        s.shapes = gen->shapes;
        s.time_step = gen->time_step;
        s.shape_set = gen->shape_set;
        s.fill = gen->fill;
        check_shapes(s.shapes);
        if (!gen->map.empty() && gen->on_map.empty()) throw InputError("--map: needs --on-map");
        check_output_path(gen->out, {gen->on_map}, "-o");
        // A physics scene may move every body in every frame.
        const double changes = is_physics_generator(s.generator) ? s.objects : s.objects * s.dynamics.change_fraction;
        check_streamed_scene_size(s.objects, s.frames, s.rays.per_frame, changes, "--objects/--frames/--rays");
        // Each frame is written as it is made (RecordingWriter): the file's bytes are those of
        // write_recording, in the memory of one frame; an error leaves no file at -o.
        RecordingWriter writer(gen->out);
        if (gen->on_map.empty())
            stream_scene(s, writer);
        else
            pile_on_map(s, gen->on_map, gen->map, writer);
        writer.finish();
        std::cout << "wrote " << gen->out << ": " << writer.objects() << " objects, " << writer.frames() << " frames, "
                  << writer.rays() << " rays\n";
    });
}

struct ImportCommandOptions {
    std::string input;
    std::string out;
    DynamicsOptions dyn;
    ImportOptions file;         // .bsp/.pk3 and model modes
    std::string motion_option;  // the first change option given (--change-fraction, ...), if any
    bool frames_given = false;  // --frames
    std::uint32_t objects = 0;  // --objects: Broadmark files only
};

/// A Broadmark file (`.aabbs`): its frames are the motion, of which --frames and --objects take the
/// first; only rays (--rays, --ray-mix, --seed) are added.
void run_broadmark_import(const ImportCommandOptions& imp) {
    if (!imp.motion_option.empty())
        throw InputError(imp.motion_option + ": a Broadmark file carries its own motion (" + imp.input + ")");
    const RaySettings rays = ray_settings(imp.dyn);
    Recording r = read_broadmark(
        imp.input, {imp.frames_given ? std::optional(imp.dyn.frames) : std::nullopt, imp.objects, rays.per_frame});
    add_rays(r, rays, imp.dyn.seed);
    nlohmann::json meta = nlohmann::json::parse(r.meta);
    meta["frames"] = r.frames.size();
    meta["seed"] = imp.dyn.seed;
    meta["rays"] = rays_json(rays);
    r.meta = meta.dump();
    write_recording(r, imp.out);
    print_written(r, imp.out);
}

/// `scene import`'s work once the options are parsed: the file's objects, dynamics and rays.
void run_import(const ImportCommandOptions& imp) {
    check_output_path(imp.out, {imp.input}, "-o");
    if (importer_for(imp.input) == "broadmark") return run_broadmark_import(imp);
    if (imp.objects) throw InputError("--objects: only for a Broadmark scene file (.aabbs), not " + imp.input);
    nlohmann::json meta;
    std::vector<Object> objects;
    if (importer_for(imp.input) != "csv") {
        objects = import_objects(imp.input, imp.file, &meta);
        if (objects.empty()) throw InputError(imp.input + ": no objects to import");
        meta["generator"] = "rcbench import";
    } else {
        objects = read_boxes_csv(imp.input);
        if (objects.empty()) throw InputError(imp.input + ": no boxes to import");
        meta = {{"generator", "rcbench import"},
                {"source", std::filesystem::path(imp.input).filename().string()},
                {"objects", objects.size()}};
    }
    const Recording r =
        add_dynamics(std::move(objects), imp.dyn.dynamics, ray_settings(imp.dyn), imp.dyn.frames, imp.dyn.seed, meta);
    write_recording(r, imp.out);
    print_written(r, imp.out);
}

/// `scene import`: a static scene from a file, given dynamics and rays.
void add_import_command(CLI::App& scene) {
    auto imp = std::make_shared<ImportCommandOptions>();
    CLI::App* i =
        scene.add_subcommand("import",
                             "Import a static scene (CSV: uid,minx,miny,minz,maxx,maxy,maxz; Quake III/OpenArena "
                             ".bsp/.pk3; any model assimp reads) and give it dynamics and rays, or a Broadmark scene "
                             "(.aabbs) with its own frames, given rays");
    i->add_option("input", imp->input,
                  "Boxes file (.csv), map (.bsp, or .pk3 with maps/*.bsp), model (.obj, .gltf, .glb, .fbx, ...) or "
                  "Broadmark scene (.aabbs: objects are uids 0..N-1, each later frame moves the boxes that changed; "
                  "--frames takes its first frames, the change options do not apply)")
        ->required()
        ->check(input_file());
    i->add_option("-o,--output", imp->out, "Recording file to write")->required();
    i->add_option(
         "--bsp-mode", imp->file.bsp_mode,
         "Maps: one box per solid brush (brushes) or one triangle object per draw-surface triangle, its box the "
         "triangle's bounds (triangles)")
        ->capture_default_str()
        ->check(CLI::IsMember({"brushes", "triangles"}));
    i->add_option("--bsp-max-triangles", imp->file.bsp_max_triangles,
                  "Maps in triangles mode: refuse a map that would make more triangles than this (a budget on the "
                  "import's time and memory that real maps stay far below; surfaces sharing their vertices can "
                  "expand a small file to millions)")
        ->capture_default_str()
        ->check(whole_number(1, kMaxSceneObjects));
    i->add_option("--map", imp->file.map, "A .pk3 holding several maps: which one (NAME or maps/NAME.bsp)");
    i->add_option("--model-mode", imp->file.model_mode,
                  "Models: one box per mesh instance (instances), the same with a rotated instance as the oriented "
                  "box of its mesh's bounds (obbs), or one triangle object per triangle in world space (triangles)")
        ->capture_default_str()
        ->check(CLI::IsMember({"instances", "obbs", "triangles"}));
    i->add_option("--objects", imp->objects,
                  "Broadmark scene files: take the first N objects (uids 0..N-1) of every frame, e.g. to stay under "
                  "the memory budget (default all)")
        ->check(whole_number(1, kMaxSceneObjects));
    add_dynamics_options(*i, imp->dyn);
    i->callback([imp, i] {
        imp->motion_option.clear();
        imp->frames_given = i->count("--frames") > 0;
        for (const char* o : {"--change-fraction", "--insert-share", "--remove-share", "--move-scale"})
            if (imp->motion_option.empty() && i->count(o) > 0) imp->motion_option = o;
        run_import(*imp);
    });
}

/// `scene export`: a recording in another tool's format.
void add_export_command(CLI::App& scene) {
    struct ExportOptions {
        std::string input, out, format;
    };
    auto ex = std::make_shared<ExportOptions>();
    CLI::App* e = scene.add_subcommand(
        "export",
        "Write a recording in another tool's format: broadmark (Broadmark's .aabbs: every object's box in frame 0 and "
        "every later frame, the header counting the later frames; no rays or shapes; refused when a frame inserts or "
        "removes objects or the recording has only frame 0)");
    e->add_option("scene", ex->input, "Recording file")->required()->check(input_file());
    e->add_option("--format", ex->format, "Output format")->required()->check(CLI::IsMember({"broadmark"}));
    e->add_option("-o,--output", ex->out, "File to write")->required();
    e->callback([ex] {
        check_output_path(ex->out, {ex->input}, "-o");
        const Recording r = read_recording(ex->input);
        write_broadmark(r, ex->out);
        std::cout << "wrote " << ex->out << ": " << r.initial.size() << " objects, frame 0 and " << r.frames.size()
                  << " frames after it, Broadmark format\n";
    });
}

struct InfoOptions {
    std::string file;
    bool json = false;
};

/// `scene info`: what a recording holds.
void add_info_command(CLI::App& scene) {
    auto info = std::make_shared<InfoOptions>();
    CLI::App* n = scene.add_subcommand(
        "info",
        "Describe a recording: format version, objects per shape kind, frames, rays, bounds, size "
        "distribution, share of objects changed per frame and per motion phase (falling, impact, settling, asleep), "
        "and moves relative to object size");
    n->add_option("file", info->file, "Recording file")->required()->check(input_file());
    n->add_flag("--json", info->json, "Print one JSON object");
    n->callback([info] { scene_info(info->file, info->json); });
}

/// `scene features`: the features derived categories are made of.
void add_features_command(CLI::App& scene) {
    auto feat = std::make_shared<InfoOptions>();
    CLI::App* fe = scene.add_subcommand(
        "features",
        "Print a recording's scene features (object count, size distribution, clustering, per-ray statistics of "
        "frame 0, change rate): what derived categories are made of");
    fe->add_option("file", feat->file, "Recording file")->required()->check(input_file());
    fe->add_flag("--json", feat->json, "Print one JSON object");
    fe->callback([feat] {
        const SceneFeatures f = compute_scene_features(read_recording(feat->file));
        if (feat->json) {
            std::cout << f.to_json().dump() << '\n';
            return;
        }
        for (std::size_t i = 0; i < kSceneFeatureCount; ++i)
            std::cout << scene_feature_names()[i] << ' ' << nlohmann::json(f.values[i]).dump() << '\n';
    });
}

/// `scene maps`: the maps inside a .pk3, by the names --map takes, for scripts that import them all.
void add_maps_command(CLI::App& scene) {
    auto file = std::make_shared<std::string>();
    CLI::App* m = scene.add_subcommand(
        "maps", "List the maps (maps/*.bsp) inside a .pk3, one per line, by the name scene import --map takes");
    m->add_option("pk3", *file, "OpenArena / Quake III package (.pk3)")->required()->check(input_file());
    m->callback([file] {
        for (const std::string& entry : pk3_maps(*file)) {
            const std::string name = std::filesystem::path(entry).stem().string();
            // Printable ASCII as it is (one line each, spaces included); a name with control or
            // non-ASCII bytes escaped, as messages show it.
            const bool plain = std::all_of(name.begin(), name.end(), [](char c) { return c >= 0x20 && c < 0x7f; });
            std::cout << (plain ? name : quoted_excerpt(name)) << '\n';
        }
    });
}

}  // namespace

void add_scene_commands(CLI::App& app) {
    CLI::App* scene = app.add_subcommand("scene", "Generate, import and inspect scene recordings");
    scene->require_subcommand(1);
    add_gen_command(*scene);
    add_import_command(*scene);
    add_export_command(*scene);
    add_info_command(*scene);
    add_features_command(*scene);
    add_maps_command(*scene);
}

}  // namespace rcb
