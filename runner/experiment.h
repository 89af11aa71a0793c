#pragma once
/// Experiment files: what to measure, declared in JSON (schema: experiments/README.md), validated
/// before anything runs, and expanded into a plan of cells (scene × configuration × repetition).

#include <cstdint>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/scene/generate/generators.h"
#include "core/base/json_input.h"
#include "accel/interface/params.h"
#include "core/scene/scene.h"

namespace rcb {

/// One concrete scene of the plan: a preset or generator with its overrides and one seed, a
/// recording file, or an imported CSV with dynamics.
struct SceneSpec {
    std::string name;    ///< for tables: the preset, the given name, or the file's stem
    nlohmann::json key;  ///< canonical description: identifies the scene in cell keys
    enum class Source { generated, recording, import } source = Source::generated;
    SceneSettings settings;         ///< generated: everything; import: dynamics, rays, frames, seed
    std::string path;               ///< recording or import: the file, resolved against the experiment's folder
    nlohmann::json import_options;  ///< import of a map or model: {"bsp_mode", "map", "model_mode"}
    std::string where;              ///< the JSON path of the entry it came from, for errors ("scenes[2]")
    /// An old key the entry used, kept for one release, as the line the command prints
    /// ("scenes[2].kind is deprecated; use \"generator\""); "" when none.
    std::string deprecated;
};

/// One structure with one complete set of parameters.
struct ConfigSpec {
    std::string structure;
    nlohmann::json params;  ///< complete: every parameter, defaults filled in
};

struct Cell {
    std::size_t scene = 0;   ///< index into Experiment::scenes
    std::size_t config = 0;  ///< index into Experiment::configs
    std::uint32_t repetition = 0;
    std::string key;  ///< stable hash of (scene key, structure, params, repetition)
};

/// Bounds on what an experiment file may ask for, checked before anything is allocated.
inline constexpr std::size_t kMaxRangeValues = 10'000;  ///< values of one {"from", "to", ...} range
inline constexpr std::size_t kMaxPlanCells = 100'000;   ///< cells of a plan, and combinations of a grid

struct Experiment {
    std::string name;
    std::string description;
    std::string content;  ///< the file's text, stored with the run
    std::string hash;     ///< of the content
    std::uint32_t repetitions = 1;
    /// Repetitions added, one round at a time, to the cells whose time is not yet pinned down: a
    /// cell whose ray-cast or update 95% interval over its repetitions so far
    /// (core/base/statistics.h) has a half-width above `repeat_interval` of its median gets
    /// another, up to this many in all. The added ones count in the cell's median and fastest
    /// frames; its stated interval rests on the `repetitions` planned before the run.
    std::uint32_t max_repetitions = 1;  ///< `repetitions` unless the file asks for more
    double repeat_interval = 0.05;
    std::uint32_t warmup_frames = 0;
    std::uint32_t threads = 1;  ///< TBB parallelism for the run (verification, threaded structures)
    bool verify = true;
    /// "cache": "cold": every frame's update starts from caches swept of the structure
    /// (sim/cache_sweep.h); "warm", the default, is the thesis' loop.
    bool cold_cache = false;
    std::vector<SceneSpec> scenes;
    std::vector<ConfigSpec> configs;
    /// Repetition-major: repetition r of every cell (scene × configuration) runs before
    /// repetition r + 1 of any, so the repetitions of one cell are spread over the whole run and
    /// their spread measures the machine's drift (the noise floor), which then biases no ratio.
    /// Each repetition visits every cell in its own seeded order, the scenes' cells interleaved
    /// (repetition_cells; the planner, runner/repetition_plan.h); the runner loads each scene once
    /// per run and keeps it.
    std::vector<Cell> plan;
};

/// The stable key of a cell: a hash of (scene key, structure, params, repetition).
std::string cell_key(const Experiment& e, std::size_t scene, std::size_t config, std::uint32_t repetition);
/// Repetition `repetition` of the given (scene, configuration) pairs, in that repetition's order:
/// every cell shuffled, the scenes' cells interleaved, seeded by the file's hash and the
/// repetition.
std::vector<Cell> repetition_cells(const Experiment& e, std::uint32_t repetition,
                                   const std::vector<std::pair<std::size_t, std::size_t>>& pairs);

/// Reads and validates; errors name the file and the JSON path, e.g.
/// "quick.json: structures[2].params.max_depth: expected an integer in 1..16, got \"x\"".
Experiment load_experiment(const std::string& path);
/// The same from text; relative file paths resolve against `base_dir`.
Experiment parse_experiment(const std::string& text, const std::string& name, const std::string& base_dir);

/// Generates, imports or reads the scene.
Recording load_scene(const SceneSpec& scene);

/// FNV-1a, 64 bits, as 16 hex digits: stable across platforms and runs.
std::string stable_hash(const std::string& bytes);

/// Defaults a scene entry inherits from the file's top level.
struct SceneDefaults {
    std::uint32_t frames = 10;
    std::uint32_t rays = 1000;
    std::string ray_mix = "center";
    std::vector<std::uint64_t> seeds{1};
};

/// A list of scene entries (the "scenes" schema of experiments/README.md); errors name `path`.
/// Two entries (or two values of one entry's "objects" or "seeds") that describe the same scene
/// are refused, naming both: they would share their cells and their stored row.
std::vector<SceneSpec> parse_scenes(const nlohmann::json& scenes, const std::string& path,
                                    const SceneDefaults& defaults, const std::string& base_dir);

/// The values one parameter takes in a grid: a value, a list, or a range {"from", "to", "step"}
/// (arithmetic) / {"from", "to", "times"} (geometric); each checked against `spec`. A range's
/// levels are from + i·step and from·times^i rounded to 12 significant digits (decimal_rounded):
/// 0.125 × √2^10 is 4.0, the default, not 4.000000000000001.
std::vector<nlohmann::json> expand_values(const ParamSpec& spec, const nlohmann::json& value, const std::string& path);

// Validation helpers for JSON files, shared by the experiment and tuning files. Every error is an
// InputError "<path>: <what>".
std::string at(const std::string& path, const std::string& key);
std::string at(const std::string& path, std::size_t index);
[[noreturn]] void fail(const std::string& path, const std::string& what);
void expect_object(const nlohmann::json& j, const std::string& path);
void check_keys(const nlohmann::json& j, const std::string& path, const std::set<std::string>& allowed);
std::uint64_t get_uint(const nlohmann::json& obj, const std::string& key, const std::string& path, std::uint64_t lo,
                       std::uint64_t hi, std::uint64_t fallback);
double get_number(const nlohmann::json& obj, const std::string& key, const std::string& path, double lo, double hi,
                  double fallback);
std::string get_string(const nlohmann::json& obj, const std::string& key, const std::string& path,
                       const std::string& fallback);
bool get_bool(const nlohmann::json& obj, const std::string& key, const std::string& path, bool fallback);
std::vector<std::uint64_t> get_uint_list(const nlohmann::json& obj, const std::string& key, const std::string& path,
                                         std::uint64_t lo, std::uint64_t hi, std::vector<std::uint64_t> fallback);
/// Reads a whole text file; InputError naming it when it cannot be opened.
std::string read_text_file(const std::string& path);

}  // namespace rcb
