#include "runner/experiment.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include "core/scene/generate/physics.h"
#include "core/scene/phases.h"
#include "core/scene/import/scene_import.h"
#include "core/base/error.h"
#include "core/base/json_input.h"
#include "core/base/number_text.h"
#include "accel/registry.h"
#include "runner/repetition_plan.h"
#include "runner/scene_windows.h"

namespace rcb {
namespace fs = std::filesystem;
using json = nlohmann::json;

std::string at(const std::string& path, const std::string& key) { return join_path(path, key); }
std::string at(const std::string& path, std::size_t index) { return path + "[" + std::to_string(index) + "]"; }

[[noreturn]] void fail(const std::string& path, const std::string& what) { throw InputError(path + ": " + what); }

void expect_object(const json& j, const std::string& path) {
    if (!j.is_object()) fail(path, "expected an object, got " + json_excerpt(j));
}

void check_keys(const json& j, const std::string& path, const std::set<std::string>& allowed) {
    for (const auto& [key, value] : j.items()) {
        if (allowed.count(key)) continue;
        fail(at(path, key), "unknown key (known: " + join(allowed) + ")");
    }
}

std::uint64_t get_uint(const json& obj, const std::string& key, const std::string& path, std::uint64_t lo,
                       std::uint64_t hi, std::uint64_t fallback) {
    if (!obj.contains(key)) return fallback;
    const json& v = obj.at(key);
    if (!(v.is_number_unsigned() || v.is_number_integer()) || v.get<double>() < double(lo) ||
        v.get<double>() > double(hi))
        fail(at(path, key),
             "expected an integer in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + json_excerpt(v));
    return v.get<std::uint64_t>();
}

double get_number(const json& obj, const std::string& key, const std::string& path, double lo, double hi,
                  double fallback) {
    if (!obj.contains(key)) return fallback;
    const json& v = obj.at(key);
    if (!v.is_number() || !(v.get<double>() >= lo && v.get<double>() <= hi)) {
        std::ostringstream range;
        range << lo << ".." << hi;
        fail(at(path, key), "expected a number in " + range.str() + ", got " + json_excerpt(v));
    }
    return v.get<double>();
}

std::string get_string(const json& obj, const std::string& key, const std::string& path, const std::string& fallback) {
    if (!obj.contains(key)) return fallback;
    if (!obj.at(key).is_string()) fail(at(path, key), "expected a string, got " + json_excerpt(obj.at(key)));
    return obj.at(key).get<std::string>();
}

bool get_bool(const json& obj, const std::string& key, const std::string& path, bool fallback) {
    if (!obj.contains(key)) return fallback;
    if (!obj.at(key).is_boolean()) fail(at(path, key), "expected true or false, got " + json_excerpt(obj.at(key)));
    return obj.at(key).get<bool>();
}

/// A list of unsigned integers given as one integer or an array of them.
std::vector<std::uint64_t> get_uint_list(const json& obj, const std::string& key, const std::string& path,
                                         std::uint64_t lo, std::uint64_t hi, std::vector<std::uint64_t> fallback) {
    if (!obj.contains(key)) return fallback;
    const json& v = obj.at(key);
    if (!v.is_array()) return {get_uint(obj, key, path, lo, hi, 0)};
    if (v.empty()) fail(at(path, key), "expected a non-empty list");
    std::vector<std::uint64_t> out;
    for (std::size_t i = 0; i < v.size(); ++i) {
        json wrapper = {{"v", v[i]}};
        try {
            out.push_back(get_uint(wrapper, "v", "", lo, hi, 0));
        } catch (const InputError& e) {
            fail(at(at(path, key), i), std::string(e.what()).substr(3));  // drop the wrapper's "v: "
        }
    }
    return out;
}

/// One level of a range: `x` as the decimal it stands for (12 significant digits, so float noise
/// does not make a second configuration of the default), within [from, to], rounded for an integer.
static json range_level(double x, double from, double to, bool integer) {
    const double level = std::clamp(decimal_rounded(x), from, to);
    return integer ? json(std::llround(level)) : json(level);
}

/// The values one parameter takes in a grid: a scalar, a list, or a range
/// {"from": a, "to": b, "step": s} (arithmetic) / {"from": a, "to": b, "times": f} (geometric).
std::vector<json> expand_values(const ParamSpec& spec, const json& v, const std::string& path) {
    std::vector<json> out;
    if (v.is_array()) {
        if (v.empty()) fail(path, "expected a non-empty list of values");
        for (std::size_t i = 0; i < v.size(); ++i) {
            check_param(spec, v[i], at(path, i));
            out.push_back(v[i]);
        }
        return out;
    }
    if (v.is_object()) {
        check_keys(v, path, {"from", "to", "step", "times"});
        if (spec.kind != ParamKind::integer && spec.kind != ParamKind::real)
            fail(path, "a range needs a numeric parameter; give " + spec.name + " a value or a list of values");
        if (!v.contains("from") || !v.contains("to") || (v.contains("step") == v.contains("times")))
            fail(path, "a range needs \"from\", \"to\" and one of \"step\" or \"times\"");
        check_param(spec, v["from"], at(path, "from"));
        check_param(spec, v["to"], at(path, "to"));
        const double from = v["from"].get<double>(), to = v["to"].get<double>();
        if (to < from) fail(path, "\"to\" is below \"from\"");
        const bool integer = spec.kind == ParamKind::integer;
        if (v.contains("step")) {
            const json& s = v["step"];
            if (!s.is_number() || !(s.get<double>() > 0) || (integer && !s.is_number_integer()))
                fail(at(path, "step"), std::string("expected a positive ") + (integer ? "integer" : "number") +
                                           ", got " + json_excerpt(s));
            const double step = s.get<double>();
            if (!((to - from) / step <= kMaxRangeValues))
                fail(path, "the range takes more than " + std::to_string(kMaxRangeValues) + " steps");
            // The last step may land a rounding past "to" (0.1 + 2 × 0.45): it is "to". Each level is
            // the decimal it stands for (range_level): 0.1 + 2 × 0.1 is 0.3.
            for (std::size_t i = 0; from + double(i) * step <= to * (1 + 1e-12) + 1e-12; ++i)
                out.push_back(range_level(from + double(i) * step, from, to, integer));
        } else {
            const json& f = v["times"];
            if (!f.is_number() || !(f.get<double>() > 1))
                fail(at(path, "times"), "expected a number above 1, got " + json_excerpt(f));
            if (!(from > 0)) fail(at(path, "from"), "a geometric range needs \"from\" above 0");
            // Count the steps before taking them: with a factor barely above 1 an integer range
            // repeats each rounded value for billions of steps (the duplicates are dropped below).
            const double steps = std::log(to / from) / std::log(f.get<double>());
            if (!(steps <= kMaxRangeValues))
                fail(path, "the range takes more than " + std::to_string(kMaxRangeValues) + " steps");
            // from × times^k, not a running product whose roundings add up (0.125 × √2 ten times
            // was 4.000000000000001 beside the default 4.0); 0.125 × √2^18 is a rounding above 64.
            for (std::size_t k = 0; k <= kMaxRangeValues; ++k) {
                const double x = from * std::pow(f.get<double>(), double(k));
                if (!(x <= to * (1 + 1e-12))) break;
                const json value = range_level(x, from, to, integer);
                if (out.empty() || out.back() != value) out.push_back(value);
            }
        }
        for (std::size_t i = 0; i < out.size(); ++i) check_param(spec, out[i], at(path, i));
        return out;
    }
    check_param(spec, v, path);
    return {v};
}

namespace {

/// Cross product of a parameter grid (keys in name order, so the expansion is stable).
std::vector<json> expand_grid(const StructureInfo& info, const json& grid, const std::string& path) {
    if (grid.is_null()) return {json::object()};
    expect_object(grid, path);
    std::vector<json> combos{json::object()};
    for (const auto& [key, value] : grid.items()) {
        auto spec = std::find_if(info.params.begin(), info.params.end(),
                                 [&, &key = key](const ParamSpec& s) { return s.name == key; });
        if (spec == info.params.end())
            check_params(info.params, json{{key, value}}, path, info.name);  // throws: unknown
        const std::vector<json> values = expand_values(*spec, value, at(path, key));
        if (combos.size() * values.size() > kMaxPlanCells)
            fail(path, "the grid has more than " + std::to_string(kMaxPlanCells) + " combinations");
        std::vector<json> next;
        for (const json& c : combos)
            for (const json& v : values) {
                json n = c;
                n[key] = v;
                next.push_back(std::move(n));
            }
        combos = std::move(next);
    }
    return combos;
}

const std::set<std::string> kSceneKeys = {
    "name",         "preset",         "generator",  "kind",           "objects",      "recording",
    "import",       "import_options", "frames",     "rays_per_frame", "ray_mix",      "change_fraction",
    "insert_share", "remove_share",   "move_scale", "rotated_share",  "sphere_share", "capsule_share",
    "seed",         "seeds",          "query_mix",  "queries",        "time_step",    "shape_set",
    "fill",         "start_frame",    "stride",     "phases"};

/// A missing file. Real maps and models are never committed: one under a data/ directory that
/// scripts/fetch_maps.sh fills is fetched on demand, so the message names the command that does.
std::string file_not_found(const std::string& file) {
    static const std::map<std::string, std::string> kFetchedBy = {{"maps", ""},
                                                                  {"models", ""},
                                                                  {"maps-unseen", " unseen"},
                                                                  {"maps-088", " fresh"},
                                                                  {"maps-085", " 085"},
                                                                  {"maps-nexuiz", " nexuiz"},
                                                                  {"tracks-torcs", " torcs"}};
    bool data = false;
    for (const fs::path& part : fs::path(file)) {
        if (data)
            if (const auto it = kFetchedBy.find(part.string()); it != kFetchedBy.end())
                return "file not found: " + file + " (scripts/fetch_maps.sh" + it->second + " fetches it)";
        data = part == "data";
    }
    return "file not found: " + file;
}

/// The frames an entry measures: one window per phase of "phases" (a name or a list of them), or
/// one from "start_frame" (default 1), each every "stride"-th frame (default 1); [null] when none
/// is given (every frame, and the key as it was).
std::vector<json> parse_measured_frames(const json& s, const std::string& path) {
    if (!s.contains("phases") && !s.contains("start_frame") && !s.contains("stride")) return {json()};
    const auto stride = get_uint(s, "stride", path, 1, 1'000'000, 1);
    if (!s.contains("phases"))
        return {{{"start_frame", get_uint(s, "start_frame", path, 1, 1'000'000, 1)}, {"stride", stride}}};
    if (s.contains("start_frame")) fail(at(path, "start_frame"), "give \"start_frame\" or \"phases\", not both");
    const json& given = s["phases"];
    const json list = given.is_array() ? given : json::array({given});
    if (list.empty()) fail(at(path, "phases"), "expected a phase or a non-empty list of phases");
    const std::vector<std::string> names = motion_phase_names();
    std::vector<json> windows;
    for (std::size_t i = 0; i < list.size(); ++i) {
        const std::string where = given.is_array() ? at(at(path, "phases"), i) : at(path, "phases");
        if (!list[i].is_string() || std::find(names.begin(), names.end(), list[i].get<std::string>()) == names.end())
            fail(where, "expected one of " + join(names) + ", got " + json_excerpt(list[i]));
        windows.push_back({{"phase", list[i]}, {"stride", stride}});
    }
    return windows;
}

/// One scene per window (parse_measured_frames), each keyed and named by it ("-settling").
void add_windows(const SceneSpec& spec, const std::vector<json>& windows, std::vector<SceneSpec>& out) {
    for (const json& window : windows) {
        out.push_back(spec);
        if (window.is_null()) continue;
        out.back().key["measure"] = window;
        if (window.contains("phase")) out.back().name.append("-").append(window["phase"].get<std::string>());
    }
}

/// A recording entry: the file brings its objects, frames, rays and dynamics.
void parse_recording_scene(const json& s, const std::string& path, const std::string& base_dir,
                           std::vector<SceneSpec>& out) {
    for (const char* k : {"objects", "frames", "rays_per_frame", "ray_mix", "query_mix", "queries", "change_fraction",
                          "insert_share", "remove_share", "move_scale", "rotated_share", "sphere_share",
                          "capsule_share", "seed", "seeds", "time_step", "shape_set", "fill"})
        if (s.contains(k)) fail(at(path, k), "a recording brings its own objects, frames, rays and dynamics");
    SceneSpec spec;
    spec.source = SceneSpec::Source::recording;
    spec.where = path;
    const std::string file = get_string(s, "recording", path, "");
    spec.path = fs::path(file).is_absolute() ? file : (fs::path(base_dir) / file).lexically_normal().string();
    if (!fs::is_regular_file(spec.path)) fail(at(path, "recording"), file_not_found(spec.path));
    spec.name = get_string(s, "name", path, fs::path(file).stem().string());
    spec.key = {{"recording", fs::path(file).filename().string()}, {"name", spec.name}};
    add_windows(spec, parse_measured_frames(s, path), out);
}

/// Where a generated or imported entry's objects come from: a preset, a generator, or a file to import.
struct SceneSource {
    SceneSettings base;
    std::string name;  ///< before "name" overrides it
    SceneSpec::Source source = SceneSpec::Source::generated;
    std::string file;
    json import_options;  ///< import: the completed ImportOptions
};

SceneSource parse_scene_source(const json& s, const std::string& path, const std::string& base_dir) {
    SceneSource src;
    if (s.contains("preset")) {
        try {
            src.base = preset_settings(get_string(s, "preset", path, ""));
        } catch (const InputError& e) {
            fail(at(path, "preset"), e.what());
        }
        src.name = src.base.preset;
    } else if (s.contains("generator") || s.contains("kind")) {
        // "kind" is the generator's old key, kept for one release.
        const char* key = s.contains("generator") ? "generator" : "kind";
        src.base.generator = get_string(s, key, path, "");
        const std::vector<std::string> generators = scene_generators();
        if (std::find(generators.begin(), generators.end(), src.base.generator) == generators.end())
            fail(at(path, key), "expected one of " + join(generators) + ", got " + json_excerpt(s[key]));
        if (!s.contains("objects")) fail(path, "a scene given by \"" + std::string(key) + "\" needs \"objects\"");
        src.name = src.base.generator;
    } else {
        src.source = SceneSpec::Source::import;
        const std::string given = get_string(s, "import", path, "");
        src.file = fs::path(given).is_absolute() ? given : (fs::path(base_dir) / given).lexically_normal().string();
        if (!fs::is_regular_file(src.file)) fail(at(path, "import"), file_not_found(src.file));
        if (s.contains("objects")) fail(at(path, "objects"), "an imported scene has the file's objects");
        src.name = fs::path(given).stem().string();
        // import_options_from_json's messages carry the JSON path already.
        src.import_options =
            to_json(import_options_from_json(s.value("import_options", json()), at(path, "import_options")));
        try {
            importer_for(src.file);
        } catch (const InputError& e) {
            fail(at(path, "import"), e.what());
        }
        if (!src.import_options["map"].get<std::string>().empty())
            src.name = src.import_options["map"].get<std::string>();
    }
    if (s.contains("import_options") && src.source != SceneSpec::Source::import)
        fail(at(path, "import_options"), "only an \"import\" scene takes import options");
    for (const char* k : {"rotated_share", "sphere_share", "capsule_share"})
        if (s.contains(k) && src.source == SceneSpec::Source::import)
            fail(at(path, k), "an imported scene has the file's shapes");
    src.name = get_string(s, "name", path, src.name);
    return src;
}

/// The entry's rays: a ray mix and a query mix, or a query preset ("queries") instead of both;
/// returns the ray mix's text (a preset's modes and weights, "fire:0.5,sight:0.3,sensor:0.2").
std::string parse_scene_rays(const json& s, const std::string& path, const SceneDefaults& d, RaySettings& rays) {
    rays.per_frame = static_cast<std::uint32_t>(get_uint(s, "rays_per_frame", path, 0, 100'000'000, d.rays));
    if (s.contains("queries")) {
        for (const char* k : {"ray_mix", "query_mix"})
            if (s.contains(k)) fail(at(path, k), "a query preset (\"queries\") sets the ray modes and their kinds");
        try {
            rays = with_query_preset(rays, get_string(s, "queries", path, ""));
        } catch (const InputError& e) {
            fail(at(path, "queries"), e.what());
        }
        std::string text;
        for (const RayMode& m : rays.mix) text += (text.empty() ? "" : ",") + m.mode + ":" + json(m.weight).dump();
        return text;
    }
    const std::string mix = get_string(s, "ray_mix", path, d.ray_mix);
    try {
        rays.mix = parse_ray_mix(mix);
    } catch (const InputError& e) {
        fail(at(path, "ray_mix"), e.what());
    }
    try {
        rays.query_mix = parse_query_mix(get_string(s, "query_mix", path, "all"));
    } catch (const InputError& e) {
        fail(at(path, "query_mix"), e.what());
    }
    return mix;
}

/// The entry's frames, rays, dynamics, shapes and time step over the file's defaults; returns the
/// ray mix's text. A physics generator's scene moves by its simulation: the dynamics keys do not apply to it,
/// and only it takes a time step.
std::string parse_scene_settings(const json& s, const std::string& path, const SceneDefaults& d, SceneSettings& base) {
    base.frames = static_cast<std::uint32_t>(get_uint(s, "frames", path, 1, 1'000'000, d.frames));
    const std::string mix = parse_scene_rays(s, path, d, base.rays);
    const bool physics = is_physics_generator(base.generator) && !s.contains("import");
    for (const char* k : {"change_fraction", "insert_share", "remove_share", "move_scale"})
        if (physics && s.contains(k))
            fail(at(path, k), "a physics generator (" + base.generator + ") moves by its simulation, not by " + k);
    if (s.contains("time_step")) {
        if (!physics)
            fail(at(path, "time_step"),
                 "only a physics generator (" + join(physics_generators()) + ") takes a time step");
        base.time_step = get_number(s, "time_step", path, 1e-4, 0.1, base.time_step);
    }
    for (const char* k : {"shape_set", "fill"})
        if (s.contains(k) && !(physics && is_broadmark_generator(base.generator)))
            fail(at(path, k), "only Broadmark's generators (brownian, freefall, gravity) take " + std::string(k));
    base.shape_set = get_string(s, "shape_set", path, base.shape_set);
    if (const auto sets = broadmark_shape_sets();
        !base.shape_set.empty() && std::find(sets.begin(), sets.end(), base.shape_set) == sets.end())
        fail(at(path, "shape_set"), "unknown set '" + base.shape_set + "' (known: " + join(sets) + ")");
    base.fill = get_number(s, "fill", path, 1e-6, 0.5, base.fill);
    base.dynamics.change_fraction = get_number(s, "change_fraction", path, 0, 1, base.dynamics.change_fraction);
    base.dynamics.insert_share = get_number(s, "insert_share", path, 0, 1, base.dynamics.insert_share);
    base.dynamics.remove_share = get_number(s, "remove_share", path, 0, 1, base.dynamics.remove_share);
    base.dynamics.move_scale = get_number(s, "move_scale", path, 0, 1000, base.dynamics.move_scale);
    if (base.dynamics.insert_share + base.dynamics.remove_share > 1)
        fail(path, "insert_share + remove_share exceeds 1");
    base.shapes.rotated_share = get_number(s, "rotated_share", path, 0, 1, 0);
    base.shapes.sphere_share = get_number(s, "sphere_share", path, 0, 1, 0);
    base.shapes.capsule_share = get_number(s, "capsule_share", path, 0, 1, 0);
    if (base.shapes.rotated_share + base.shapes.sphere_share + base.shapes.capsule_share > 1)
        fail(path, "rotated_share + sphere_share + capsule_share exceeds 1");
    return mix;
}

/// One concrete scene of an entry: its object count and seed, its name and its key.
SceneSpec concrete_scene(const SceneSource& src, const SceneSettings& base, const std::string& mix, std::uint64_t count,
                         std::uint64_t seed, bool many_counts, bool many_seeds) {
    SceneSpec spec;
    spec.source = src.source;
    spec.settings = base;
    spec.settings.seed = seed;
    spec.path = src.file;
    if (src.source != SceneSpec::Source::import) spec.settings.objects = static_cast<std::uint32_t>(count);
    spec.name = src.name;
    if (many_counts) spec.name.append("-").append(std::to_string(count));
    if (many_seeds) spec.name.append("-s").append(std::to_string(seed));
    json dyn = {{"change_fraction", base.dynamics.change_fraction},
                {"insert_share", base.dynamics.insert_share},
                {"remove_share", base.dynamics.remove_share},
                {"move_scale", base.dynamics.move_scale}};
    spec.key = {{"frames", base.frames},
                {"rays_per_frame", base.rays.per_frame},
                {"ray_mix", mix},
                {"dynamics", dyn},
                {"seed", seed}};
    // Only when some ray is not `all`: an all-hits scene's key (its results' identity) stays as it was.
    if (!asks_all_only(base.rays.query_mix)) spec.key["query_mix"] = query_mix_json(base.rays.query_mix);
    if (!base.rays.queries.empty()) spec.key["queries"] = base.rays.queries;
    // A physics scene's time step, only when it is not the default: older keys stay as they were.
    if (is_physics_generator(base.generator) && src.source != SceneSpec::Source::import &&
        base.time_step != SceneSettings{}.time_step)
        spec.key["time_step"] = base.time_step;
    // Broadmark's shape set and fill, only when given: older keys stay as they were.
    if (!base.shape_set.empty()) spec.key["shape_set"] = base.shape_set;
    if (base.fill != 0) spec.key["fill"] = base.fill;
    if (src.source == SceneSpec::Source::import) {
        spec.key["import"] = fs::path(src.file).filename().string();
        if (importer_for(src.file) != "csv") spec.key["import_options"] = spec.import_options = src.import_options;
    } else {
        // The stored key keeps the generator's old name, as every stored run does.
        spec.key["kind"] = base.generator, spec.key["objects"] = count;
        // Only when set: a box scene's key (and so its results' identity) stays as it was.
        if (base.shapes.any())
            spec.key["shapes"] = {{"rotated_share", base.shapes.rotated_share},
                                  {"sphere_share", base.shapes.sphere_share},
                                  {"capsule_share", base.shapes.capsule_share}};
    }
    return spec;
}

void parse_scene(const json& s, const std::string& path, const SceneDefaults& d, const std::string& base_dir,
                 std::vector<SceneSpec>& out) {
    expect_object(s, path);
    check_keys(s, path, kSceneKeys);
    int sources = int(s.contains("preset")) + int(s.contains("generator")) + int(s.contains("kind")) +
                  int(s.contains("recording")) + int(s.contains("import"));
    if (sources != 1) fail(path, "give exactly one of \"preset\", \"generator\", \"recording\" or \"import\"");
    if (s.contains("recording")) return parse_recording_scene(s, path, base_dir, out);

    SceneSource src = parse_scene_source(s, path, base_dir);
    const std::vector<std::uint64_t> objects =
        src.source == SceneSpec::Source::import ? std::vector<std::uint64_t>{0}
                                                : get_uint_list(s, "objects", path, 1, 100'000'000, {src.base.objects});
    std::vector<std::uint64_t> seeds = d.seeds;
    if (s.contains("seed") && s.contains("seeds")) fail(path, "give \"seed\" or \"seeds\", not both");
    if (s.contains("seed")) seeds = {get_uint(s, "seed", path, 0, UINT64_MAX, 1)};
    if (s.contains("seeds")) seeds = get_uint_list(s, "seeds", path, 0, UINT64_MAX, d.seeds);
    const std::string mix = parse_scene_settings(s, path, d, src.base);
    const std::vector<json> windows = parse_measured_frames(s, path);
    for (std::uint64_t count : objects)
        for (std::uint64_t seed : seeds) {
            SceneSpec spec = concrete_scene(src, src.base, mix, count, seed, objects.size() > 1, seeds.size() > 1);
            spec.where = path;
            if (s.contains("kind")) spec.deprecated = at(path, "kind") + " is deprecated; use \"generator\"";
            add_windows(spec, windows, out);
        }
}

/// Two entries describing one scene would share its cells (a cell's key holds the scene's key, not
/// its name) and its stored row (scenes are stored by content): the second name would get no cells.
void refuse_duplicate_scenes(const std::vector<SceneSpec>& scenes) {
    std::map<std::string, std::size_t> by_key, by_file;
    for (std::size_t i = 0; i < scenes.size(); ++i) {
        const SceneSpec& s = scenes[i];
        std::optional<std::size_t> first;
        if (auto [it, added] = by_key.emplace(s.key.dump(), i); !added) first = it->second;
        if (!first && s.source == SceneSpec::Source::recording) {
            std::error_code ec;
            const fs::path file = fs::weakly_canonical(s.path, ec);
            // One file measured in several windows is several scenes.
            const std::string window = s.key.contains("measure") ? s.key["measure"].dump() : "";
            if (auto [it, added] = by_file.emplace((ec ? s.path : file.string()) + window, i); !added)
                first = it->second;
        }
        if (!first) continue;
        const SceneSpec& f = scenes[*first];
        if (f.where == s.where)
            fail(s.where, "gives the scene \"" + s.name + "\" twice (a value repeated in \"objects\" or \"seeds\")");
        fail(s.where, "the same scene as " + f.where + " (\"" + f.name + "\" and \"" + s.name +
                          "\"): their cells would be stored as one; make them differ or drop one");
    }
}

}  // namespace

std::vector<SceneSpec> parse_scenes(const json& scenes, const std::string& path, const SceneDefaults& d,
                                    const std::string& base_dir) {
    if (!scenes.is_array() || scenes.empty()) fail(path, "expected a non-empty list of scenes");
    std::vector<SceneSpec> out;
    for (std::size_t i = 0; i < scenes.size(); ++i) parse_scene(scenes[i], at(path, i), d, base_dir, out);
    refuse_duplicate_scenes(out);
    return out;
}

std::string read_text_file(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw InputError(path + ": cannot open");
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

std::string stable_hash(const std::string& bytes) {
    std::uint64_t h = 0xcbf29ce484222325ULL;
    for (unsigned char c : bytes) {
        h ^= c;
        h *= 0x100000001b3ULL;
    }
    char out[17];
    std::snprintf(out, sizeof out, "%016llx", static_cast<unsigned long long>(h));
    return out;
}

namespace {

/// The run's "threads" caps every TBB arena of the process, a structure's own threads included:
/// a configuration asking for more would be measured on fewer. Checked on every expanded value,
/// so a list, a range ({"from", "to", "step" or "times"}) and a single value are held alike.
void check_thread_cap(const json& params, std::uint32_t threads, const std::string& path) {
    for (const char* key : {"threads", "cast_threads"}) {
        if (!params.contains(key) || !params[key].is_number_integer()) continue;
        const std::int64_t asked = params[key].get<std::int64_t>();
        if (asked > std::int64_t(threads))
            fail(at(path, key), std::to_string(asked) + " threads, more than the experiment's \"threads\" (" +
                                    std::to_string(threads) +
                                    "), which caps every thread of the run: set \"threads\" to at least " +
                                    std::to_string(asked));
    }
}

/// One "structures" entry's parameter sets: its "params", or each of its "grids", with the path of each.
std::vector<std::pair<json, std::string>> structure_grids(const json& s, const std::string& path) {
    if (s.contains("params") && s.contains("grids")) fail(path, "give \"params\" or \"grids\", not both");
    std::vector<std::pair<json, std::string>> grids;
    if (!s.contains("grids")) {
        grids.emplace_back(s.contains("params") ? s["params"] : json::object(), at(path, "params"));
        return grids;
    }
    if (!s["grids"].is_array() || s["grids"].empty())
        fail(at(path, "grids"), "expected a non-empty list of parameter grids");
    for (std::size_t g = 0; g < s["grids"].size(); ++g) grids.emplace_back(s["grids"][g], at(at(path, "grids"), g));
    return grids;
}

/// The distinct configurations of the "structures" list, grids expanded, in the file's order.
std::vector<ConfigSpec> parse_configs(const json& j, std::uint32_t threads) {
    if (!j.contains("structures") || !j["structures"].is_array() || j["structures"].empty())
        fail("structures", "expected a non-empty list of structures");
    std::vector<ConfigSpec> configs;
    std::set<std::string> seen;
    for (std::size_t i = 0; i < j["structures"].size(); ++i) {
        const json& s = j["structures"][i];
        const std::string path = at("structures", i);
        expect_object(s, path);
        check_keys(s, path, {"name", "params", "grids"});
        if (!s.contains("name")) fail(path, "missing \"name\"");
        const StructureInfo* info = nullptr;
        try {
            info = &find_structure(get_string(s, "name", path, ""));
        } catch (const InputError& err) {
            fail(at(path, "name"), err.what());
        }
        for (const auto& [grid, gpath] : structure_grids(s, path))
            for (const json& params : expand_grid(*info, grid, gpath)) {
                ConfigSpec c{info->name, info->complete(params, gpath)};
                check_thread_cap(c.params, threads, gpath);
                if (seen.insert(c.structure + c.params.dump()).second) configs.push_back(std::move(c));
                if (configs.size() > kMaxPlanCells)
                    fail("structures", "more than " + std::to_string(kMaxPlanCells) + " configurations");
            }
    }
    return configs;
}

}  // namespace

std::string cell_key(const Experiment& e, std::size_t scene, std::size_t config, std::uint32_t repetition) {
    const json key = {{"scene", e.scenes[scene].key},
                      {"structure", e.configs[config].structure},
                      {"params", e.configs[config].params},
                      {"repetition", repetition}};
    return stable_hash(key.dump());
}

namespace {

/// The seed of the plan's order: the file's hash (stable_hash, hexadecimal).
std::uint64_t plan_seed(const Experiment& e) { return std::stoull(e.hash, nullptr, 16); }

/// The cell of a planned run whose item indexes `pairs` (scene, configuration).
Cell cell_of(const Experiment& e, const std::vector<std::pair<std::size_t, std::size_t>>& pairs, PlannedRun run) {
    const auto [s, c] = pairs[run.item];
    return {s, c, run.repetition, cell_key(e, s, c, run.repetition)};
}

}  // namespace

std::vector<Cell> repetition_cells(const Experiment& e, std::uint32_t repetition,
                                   const std::vector<std::pair<std::size_t, std::size_t>>& pairs) {
    // Every cell of the repetition in the planner's order shuffled by the file's hash and the
    // repetition (runner/repetition_plan.h; the same file gives the same order), the scenes
    // interleaved: a stretch of minutes in which the machine runs slow falls on cells of many
    // scenes rather than on one scene's (docs/model.md as of commit
    // f3b2207, "How well two runs agree").
    std::vector<Cell> cells;
    for (std::size_t i : repetition_order(pairs.size(), repetition, plan_seed(e)))
        cells.push_back(cell_of(e, pairs, {repetition, i}));
    return cells;
}

namespace {

/// Every (scene, configuration) pair of the experiment.
std::vector<std::pair<std::size_t, std::size_t>> all_pairs(const Experiment& e) {
    std::vector<std::pair<std::size_t, std::size_t>> pairs;
    for (std::size_t s = 0; s < e.scenes.size(); ++s)
        for (std::size_t c = 0; c < e.configs.size(); ++c) pairs.emplace_back(s, c);
    return pairs;
}

}  // namespace

Experiment parse_experiment(const std::string& text, const std::string& name, const std::string& base_dir) {
    const json j = parse_json_document(text, name);
    try {
        expect_object(j, "(top level)");
        // The range criterion's key, replaced by the interval's: named, so an old file says what to write.
        if (j.contains("repeat_spread"))
            fail("repeat_spread",
                 "replaced by repeat_interval (the 95% interval's half-width over repetitions as a fraction of the "
                 "median; experiments/README.md)");
        check_keys(
            j, "",
            {"name", "description", "frames", "warmup_frames", "repetitions", "max_repetitions", "repeat_interval",
             "rays_per_frame", "ray_mix", "seeds", "threads", "verify", "cache", "scenes", "structures"});
        Experiment e;
        e.content = text;
        e.hash = stable_hash(text);
        e.name = get_string(j, "name", "", fs::path(name).stem().string());
        if (e.name.empty()) fail("name", "must not be empty");
        e.description = get_string(j, "description", "", "");
        e.repetitions = static_cast<std::uint32_t>(get_uint(j, "repetitions", "", 1, 1000, 1));
        // None added unless asked: a plan's size then depends on nothing measured.
        e.max_repetitions =
            static_cast<std::uint32_t>(get_uint(j, "max_repetitions", "", e.repetitions, 1000, e.repetitions));
        e.repeat_interval = get_number(j, "repeat_interval", "", 0, 10, e.repeat_interval);
        e.warmup_frames = static_cast<std::uint32_t>(get_uint(j, "warmup_frames", "", 0, 1000, 0));
        e.threads = static_cast<std::uint32_t>(get_uint(j, "threads", "", 1, 1024, 1));
        e.verify = get_bool(j, "verify", "", true);
        const std::string cache = get_string(j, "cache", "", "warm");
        if (cache != "warm" && cache != "cold")
            fail("cache", "expected \"warm\" or \"cold\", got " + json_excerpt(j["cache"]));
        e.cold_cache = cache == "cold";
        SceneDefaults d;
        d.frames = static_cast<std::uint32_t>(get_uint(j, "frames", "", 1, 1'000'000, d.frames));
        d.rays = static_cast<std::uint32_t>(get_uint(j, "rays_per_frame", "", 0, 100'000'000, d.rays));
        d.ray_mix = get_string(j, "ray_mix", "", d.ray_mix);
        d.seeds = get_uint_list(j, "seeds", "", 0, UINT64_MAX, d.seeds);

        if (!j.contains("scenes")) fail("scenes", "expected a non-empty list of scenes");
        e.scenes = parse_scenes(j["scenes"], "scenes", d, base_dir);
        for (const SceneSpec& s : e.scenes)
            if (s.source != SceneSpec::Source::recording && e.warmup_frames >= s.settings.frames)
                fail("warmup_frames", "leaves no measured frame in scene " + s.name);

        e.configs = parse_configs(j, e.threads);

        // Refuse an oversized plan before allocating it (a typo such as 1000 repetitions of a
        // 6400-value grid would otherwise take minutes and gigabytes to expand).
        const double cells = double(e.scenes.size()) * double(e.configs.size()) * double(e.repetitions);
        if (cells > double(kMaxPlanCells))
            fail("(top level)", "the plan has " + std::to_string(std::uint64_t(cells)) + " cells (" +
                                    std::to_string(e.scenes.size()) + " scenes x " + std::to_string(e.configs.size()) +
                                    " configurations x " + std::to_string(e.repetitions) +
                                    " repetitions), more than the limit of " + std::to_string(kMaxPlanCells) +
                                    "; split it into several experiment files");
        e.plan.reserve(std::size_t(cells));
        const std::vector<std::pair<std::size_t, std::size_t>> pairs = all_pairs(e);
        for (const PlannedRun& p : repetition_plan(pairs.size(), e.repetitions, plan_seed(e)))
            e.plan.push_back(cell_of(e, pairs, p));
        return e;
    } catch (const InputError& err) {
        throw InputError(name + ": " + err.what());
    }
}

Experiment load_experiment(const std::string& path) {
    if (fs::is_directory(path)) throw InputError(path + ": is a directory, not an experiment file");
    return parse_experiment(read_text_file(path), path, fs::path(path).parent_path().string());
}

Recording load_scene(const SceneSpec& s) {
    Recording r = load_scene_frames(s);
    r.meta = measured_meta(s, r);
    return r;
}

}  // namespace rcb
