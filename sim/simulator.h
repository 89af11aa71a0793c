#pragma once
/// The simulator (thesis §5.2.2): replays a recording against one structure.
///
///     build (timed)
///     per frame:  with a cold cache, read a buffer larger than every cache (cache_sweep.h)
///                 apply the frame's changes + commit (timed: update)
///                 cast the frame's rays as one batch, each with its query kind (timed: ray cast)
///                 verify every ray's hits against the ground truth (not timed): the
///                 configuration's contract (query_level.h) and its accuracy against the shapes
///                 the counting pass: the same rays with counters on (not timed)
///
/// Timing wraps whole phases, never a single ray (core/base/stopwatch.h): with the thread's CPU
/// time when the configuration's work runs on one thread, so a time slice another process takes
/// on the core is not counted as the structure's cost; with the wall time otherwise. Both are
/// kept per frame.
///
/// A frame whose rays ask for more than one query kind casts them as one timed batch per kind
/// (the rays of that kind in recording order; the batches are copied out before any timing), and
/// counts them per kind the same way; the answers are put back in recording order for the
/// verification. An engine issues its shots, visibility checks and sensor sweeps as separate
/// batches, and only a batch of one kind has a time of its own: the cost model's check that its
/// coefficients do not depend on the kind (docs/model.md) needs each kind's time beside its
/// counters. A frame of one kind is cast exactly as a frame of all hits is: one call, one timing.
/// With `cast_threads` > 1 every timed batch, of whatever kind, runs on the structure's threads
/// (structure.h, StructureBase); the counting pass runs on the calling thread, so a frame's hits
/// and counters do not depend on the thread count.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/model/counters.h"
#include "core/base/statistics.h"
#include "core/base/stopwatch.h"
#include "sim/cache_sweep.h"
#include "core/truth/ground_truth.h"
#include "accel/registry.h"
#include "core/scene/scene.h"

namespace rcb {

struct SimulationOptions {
    bool verify = true;  ///< compare every ray with the ground truth
    bool count = true;   ///< run the counting pass
    bool timed_cast =
        true;  ///< time the ray batch; false: only the counting pass casts (the tuner's cheap prediction runs)
    /// Time the build and every frame's update; false: neither is timed (their times read 0). With
    /// timed_cast false too the run is an untimed replay: it counts and times nothing (untimed_replay).
    bool timed_update = true;
    bool check = false;               ///< call Structure::check() after the build and every commit
    bool validate = false;            ///< check's old name, for one release: either turns the checks on
    std::uint32_t max_frames = 0;     ///< replay at most this many frames (0: all)
    std::uint32_t warmup_frames = 0;  ///< the first frames run but are left out of the summaries
    /// nullptr: warm, the thesis' loop (each phase meets the cache as the last left it). Otherwise
    /// every frame's update starts cold: this buffer is read first (cache_sweep.h). Shared, so a
    /// run makes and touches it once, not once per cell.
    std::shared_ptr<const CacheSweep> cold_cache;
};

/// One query kind's share of a frame that has rays of another kind than `all`: its rays, their
/// timed batch (both clocks), the hits it reported and its counting pass.
struct KindResult {
    QueryKind kind = QueryKind::all;
    std::uint32_t rays = 0;
    std::uint64_t raycast_ns = 0;  ///< on the result's clock
    Elapsed raycast;
    std::uint64_t hits = 0;
    Counters counters;
};

struct FrameResult {
    std::uint32_t frame = 0;  ///< 1-based; frame 0 is the build
    bool warmup = false;
    std::uint32_t inserts = 0, removes = 0, moves = 0, rays = 0;
    std::uint32_t closest = 0, any = 0;  ///< of the rays, those asking for the closest hit and any hit
    std::uint64_t writes = 0;            ///< cells, entries and nodes the update wrote (Structure::writes)
    std::uint64_t update_work = 0;       ///< the update's work beyond its writes (Structure::update_work)
    std::uint64_t update_ns = 0;         ///< on the result's clock
    std::uint64_t raycast_ns = 0;        ///< on the result's clock
    Elapsed update, raycast;             ///< both clocks (wall − CPU: time the thread waited)
    std::uint64_t hits = 0;              ///< reported by the timed pass, summed over the rays
    std::uint64_t missed = 0, extra = 0, duplicate = 0;  ///< against the configuration's contract
    /// Accuracy against the shapes' truth (ground_truth.h, Verification): recall = correct /
    /// relevant, precision = correct / returned.
    std::uint64_t returned = 0, correct = 0, relevant = 0;
    Counters counters;  ///< from the counting pass, summed over the rays
    /// Per query kind present, in kind order (all, closest, any); empty when every ray asks for all
    /// hits. Rays, times, hits and counters sum to the frame's.
    std::vector<KindResult> kinds;
    std::uint64_t memory_bytes = 0;
    nlohmann::json stats;  ///< Structure::stats() after the frame's commit

    std::uint64_t mismatches() const { return missed + extra + duplicate; }
    /// 1 when nothing is expected (no true hits) or nothing returned.
    double recall() const { return relevant ? double(correct) / double(relevant) : 1.0; }
    double precision() const { return returned ? double(correct) / double(returned) : 1.0; }
};

struct SimulationResult {
    std::string structure;
    nlohmann::json params;  ///< complete: defaults filled in
    std::size_t objects = 0;
    TimingClock clock = TimingClock::wall;  ///< what build_ns, update_ns and raycast_ns measure
    std::uint64_t cold_cache_bytes = 0;     ///< SimulationOptions' (0: warm)
    std::uint64_t build_ns = 0;
    std::uint64_t memory_bytes = 0;  ///< after the build
    std::vector<FrameResult> frames;
    std::vector<std::pair<std::uint32_t, Discrepancy>> examples;  ///< (frame, discrepancy), the first few
    bool verified = false;

    std::uint64_t mismatches() const;
    /// Over the frames that are not warm-up.
    Spread update_ns() const;
    Spread raycast_ns() const;
    nlohmann::json to_json() const;
};

/// The options of an untimed counting replay: the counting pass is the only cast and nothing (build,
/// update, rays) is timed, so a prediction from its counters spends no timed run on the scene.
SimulationOptions untimed_replay(std::uint32_t warmup_frames);

/// How many phases simulate() has timed in this process (a build, a frame's update, a ray batch):
/// what tests read to check that a replay called untimed times nothing.
std::uint64_t timed_phases();

/// Called after each frame (for progress reports); may be empty.
using FrameCallback = std::function<void(const FrameResult&)>;

/// InputError when `warmup_frames` leave none of `frames` to measure (simulate checks it too).
void check_warmup(std::size_t warmup_frames, std::size_t frames);

/// `params` is validated against the structure's registry entry (errors name `params_path`).
SimulationResult simulate(const Recording& recording, const StructureInfo& structure, const nlohmann::json& params,
                          const SimulationOptions& options = {}, const std::string& params_path = "params",
                          const FrameCallback& on_frame = {});

}  // namespace rcb
