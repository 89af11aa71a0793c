#pragma once
/// The machine behind a run: its cache sizes, and a calibration pass that measures each structure
/// on designed micro-scenes.
///
/// In a real scene the counters of eq. 5.4 (thesis §5.1) move together: in a BVH every node visit
/// leads to box tests, so N_RB and N_T are nearly collinear and a fit cannot tell C_RB from C_T.
/// The micro-scenes vary them independently: rays outside every object's bounds (start-up only:
/// C_PREP), rays through the empty inside of a hollow shell (traversal steps with few tests: C_T),
/// the same shell crossed again and again by one ray (the same steps, each predicted from the ray
/// before: C_MP, the extra cost of an unpredicted step), a stack of identical boxes every ray
/// crosses (box tests that all hit, with few steps in a grid, the whole tree in a BVH), a cluster of
/// small boxes that rays cross and seldom hit (a grid's cells there hold some thirty boxes each, as
/// in a scene's dense region: C_RB apart from C_HIT, what reporting a hit costs), and rays along the
/// gaps and rows of a lattice and random segments across it (mixes). All but two are small, so the
/// coefficients they give are in-cache costs; long and short random segments across a lattice of
/// 32768 boxes, whose nodes and cells outgrow a core's private cache, fetch lines (N_MISS:
/// C_MISS). Each timed repeat casts new rays of the scene's kind, as a run's frames do. The
/// analysis stage fits them (the priors of the run's fit); this stage only measures and stores.

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/registry.h"
#include "runner/sqlite.h"

namespace rcb {

/// One data or unified cache of the CPU (instruction caches are left out).
struct CacheLevel {
    int level = 0;
    std::string type;  ///< "Data" or "Unified"
    std::uint64_t bytes = 0;
};

/// "32K", "1024K", "8M", "512" → bytes; InputError naming `where` for anything else.
std::uint64_t parse_cache_size(const std::string& text, const std::string& where);

/// The caches under `dir` (sysfs: index*/{level,type,size}), sorted by level. A missing folder
/// gives none (a machine without sysfs); a malformed entry is an InputError naming its file.
std::vector<CacheLevel> read_cache_sizes(const std::string& dir = "/sys/devices/system/cpu/cpu0/cache");

/// The buffer a cold-cache run reads before each update (sim/cache_sweep.h): twice the
/// largest of `caches`, so no line of a smaller working set survives a sweep whatever the
/// replacement policy; 64 MiB when the machine reports no cache.
std::uint64_t cold_sweep_bytes(const std::vector<CacheLevel>& caches = read_cache_sizes());

/// One micro-scene measured: mean counters per ray and the median time per ray over repeats.
struct CalibrationPoint {
    std::string scene;
    std::uint32_t rays = 0;
    double n_rb = 0, n_t = 0;  ///< per ray
    double ns_per_ray = 0;     ///< median over the repeats
    double mad = 0;            ///< median absolute deviation over the repeats
    double n_mp = 0;           ///< steps the history predictor missed, per ray (accel/model/outcome_predictor.h)
    /// Lines the simulated private cache fetched, per ray (accel/model/cache_model.h), for each timed
    /// batch as it met the cache: after the batch before it.
    double n_miss = 0;
    double n_tp = 0;   ///< objects reported per ray: prices C_HIT apart from C_RB
    double n_dup = 0;  ///< box hits a grid dropped as already reported, per ray
    int passes = 1;    ///< calibration passes of the run this point is the fastest of (load_calibration)
    /// Batches of `rays` both timed and counted: the time is their median, the counters their mean.
    int repeats = 0;
    /// Whether the structure's calibration budget (kCalibrationBudgetSeconds) cut this point short:
    /// fewer batches than asked for, or kCutRays rays per batch.
    bool cut = false;
};

/// The calibration's own time (the lesser of its wall and its thread's CPU time,
/// core/base/stopwatch.h: a loaded machine does not spend it) for a structure a program registered
/// (register_structure) or describes without registering. A slow one (a list scanned per ray, a
/// structure that counts many steps per ray) stops counting batches once it is spent, and measures
/// the micro-scenes after that on kCutRays rays with one batch, so that it costs seconds rather than
/// minutes; such points are recorded as cut. rcbench's own structures are measured in full, whatever
/// they take (the ODE peers' spaces are the slowest), so their points stay as they were.
inline constexpr double kCalibrationBudgetSeconds = 4.0;
/// Rays per batch of a micro-scene begun after the budget was spent: the first rays of its batches.
inline constexpr int kCutRays = 32;

/// Whether `scene` is a micro-scene whose structure outgrows a core's private cache (the lattice of
/// 32768 boxes): its time includes the lines fetched, which only a structure that counts N_MISS can
/// tell apart from its box tests and steps.
bool outgrows_cache(const std::string& scene);

/// Whether `scene` is the micro-scene that prices a reported hit apart from a box test (the
/// cluster): a fit without C_HIT leaves it out.
bool prices_hits(const std::string& scene);

/// The budget calibrate_structure gives `info` by default: none (infinity) for rcbench's own
/// structures (accel/builtin_structures.h), kCalibrationBudgetSeconds for any other.
double calibration_budget(const StructureInfo& info);

/// Builds `info` with `params` on every micro-scene and times `repeats` (1 to 255) batches of new
/// rays after a warm-up batch; the counters are the timed batches' mean. Deterministic scenes and
/// rays. A structure that cannot be built on the large lattice (a user's, with limits of its own)
/// goes without those points. Its time grows with the structure's build and ray costs; a slow one of
/// a program's own is cut short by the budget below.
/// `budget_seconds` of the calibration's own time (negative: calibration_budget(info)): once spent, the
/// counting of the scene under way stops after the batch it counts (each point keeps at least one
/// batch, and the times of the batches it counted), and every later scene is measured with one
/// batch of kCutRays rays after a warm-up batch as large. The budget is checked outside the timed
/// casts only, so it changes nothing of a calibration that does not spend it.
std::vector<CalibrationPoint> calibrate_structure(const StructureInfo& info, const nlohmann::json& params,
                                                  int repeats = 7, double budget_seconds = -1);

/// calibrate_structure for the registered structure `name`, or no points when it cannot be built
/// on the micro-scenes (a user's structure with its own limits): its fits then go without priors
/// and say so.
std::vector<CalibrationPoint> calibrate_if_buildable(const std::string& name, const nlohmann::json& params);

/// (name, complete params) pairs, one per structure of an experiment.
using CalibratedStructures = std::vector<std::pair<std::string, nlohmann::json>>;

/// Stores the caches and each structure's first calibration pass with the run (tables run_cache
/// and calibration, docs/database.md), unless the run has them already (a resumed run keeps its
/// own). Returns whether it measured.
bool record_machine(Database& db, std::int64_t run, const CalibratedStructures& structures,
                    const std::string& cache_dir = "/sys/devices/system/cpu/cpu0/cache");

/// Measures and stores another calibration pass of every structure (the run's next pass number).
/// A pass takes seconds and the host's slow stretches last about a minute (docs/model.md as of commit f3b2207, "Hits
/// apart from tests, judged on maps-oacmp2"), so one pass can fall in one whole; passes minutes
/// apart seldom all do, and each micro-scene's fastest pass is what a quiet machine measures.
void add_calibration_pass(Database& db, std::int64_t run, const CalibratedStructures& structures);

/// The stored caches of a run (empty for runs made before they were stored).
std::vector<CacheLevel> load_cache_sizes(Database& db, std::int64_t run);

/// A structure's calibration in a run: per micro-scene (in the order first stored) its fastest
/// pass, with `passes` the number of passes; empty for runs made before calibrations were stored.
std::vector<CalibrationPoint> load_calibration(Database& db, std::int64_t run, const std::string& structure);

}  // namespace rcb
