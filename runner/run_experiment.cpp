#include "runner/run_experiment.h"

#include <fcntl.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <memory>
#include <numeric>
#include <set>
#include <thread>

#include "core/base/error.h"
#include "core/base/random.h"
#include "core/base/statistics.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "runner/calibration.h"
#include "runner/scene_windows.h"
#include "runner/binary_identity.h"
#include "runner/store.h"

namespace rcb {

std::vector<Cell> shard_plan(const Experiment& e, std::size_t shard_k, std::size_t shard_n) {
    std::vector<Cell> plan;
    for (std::size_t i = 0; i < e.plan.size(); ++i)
        if (i % shard_n == shard_k - 1) plan.push_back(e.plan[i]);
    return plan;
}

std::string config_label(const ConfigSpec& c) {
    const nlohmann::json defaults = find_structure(c.structure).defaults();
    std::string changed;
    for (const auto& [k, v] : c.params.items())
        if (!defaults.contains(k) || defaults[k] != v) changed += (changed.empty() ? "" : ",") + k + "=" + v.dump();
    return changed.empty() ? c.structure : c.structure + " " + changed;
}

namespace {

/// The median wall time of three passes of `pass(k)` (k = 0, 1, 2), in ns.
template <typename Pass>
double median_of_three_passes(Pass pass) {
    std::vector<double> ns;
    for (int k = 0; k < 3; ++k) {
        const auto start = std::chrono::steady_clock::now();
        pass(k);
        ns.push_back(double(
            std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count()));
    }
    return median(ns);
}

}  // namespace

MachineState sample_machine_state() {
    MachineState m;
    m.load_1m = -1;
    if (std::ifstream in("/proc/loadavg"); in) in >> m.load_1m;
    if (!std::isfinite(m.load_1m)) m.load_1m = -1;
    m.calibration_ns = median_of_three_passes([](int k) {
        std::uint64_t x = 0x9e3779b97f4a7c15ULL + std::uint64_t(k);
        for (int i = 0; i < 750'000; ++i) x = x * 6364136223846793005ULL + 1442695040888963407ULL;
        // The result is used, so the chain cannot be folded away.
        volatile std::uint64_t sink = x;
        (void)sink;
    });
    m.memory_ns = memory_probe_ns();
    return m;
}

double memory_probe_ns() {
    // One cycle through 8 MiB of 4-byte indices, visiting them in a shuffled order (fixed seed),
    // built once: each step's load depends on the last, so the time is the latency of the caches
    // and memory a process on the other core competes for.
    constexpr std::size_t kEntries = std::size_t(8) << 18;  // 8 MiB of std::uint32_t
    constexpr int kSteps = 100'000;
    static const std::vector<std::uint32_t> cycle = [] {
        std::vector<std::uint32_t> order(kEntries), next(kEntries);
        std::iota(order.begin(), order.end(), std::uint32_t{0});
        Random(0x6d656d70726f6265ULL).shuffle(order);
        for (std::size_t i = 0; i < kEntries; ++i) next[order[i]] = order[(i + 1) % kEntries];
        return next;
    }();
    std::uint32_t at = 0;
    const double ns = median_of_three_passes([&](int) {
        for (int i = 0; i < kSteps; ++i) at = cycle[at];
    });
    volatile std::uint32_t sink = at;  // the chain's result is used, so it cannot be folded away
    (void)sink;
    return ns;
}

namespace {

/// One runner per database at a time: two runners of one plan would each measure every cell they
/// find undone (storing one result and throwing the other away), and would slow each other's
/// timings. An open-file-description lock on one byte of the database far past SQLite's own lock
/// bytes (which start at 1 GiB, sqlite3 os_unix.c), so it conflicts with no lock SQLite takes, is
/// released when the process dies, and needs no lock file beside the database.
class RunnerLock {
public:
    RunnerLock(const std::string& db, const std::function<void()>& on_wait) : db_(db) {
        fd_ = ::open(db.c_str(), O_RDWR | O_CLOEXEC);
        if (fd_ < 0) throw InputError(db + ": cannot open the results database (" + std::strerror(errno) + ")");
        struct flock l = byte();
        if (::fcntl(fd_, F_OFD_SETLK, &l) == 0) return;
        if (errno != EAGAIN && errno != EACCES) fail("lock");
        if (on_wait) on_wait();
        l = byte();
        while (::fcntl(fd_, F_OFD_SETLKW, &l) != 0)
            if (errno != EINTR) fail("wait for");
    }
    ~RunnerLock() { ::close(fd_); }  // closing the description releases its lock
    RunnerLock(const RunnerLock&) = delete;
    RunnerLock& operator=(const RunnerLock&) = delete;

private:
    static struct flock byte() {
        struct flock l {};
        l.l_type = F_WRLCK;
        l.l_whence = SEEK_SET;
        l.l_start = (off_t(1) << 30) + 4096;
        l.l_len = 1;
        return l;
    }
    [[noreturn]] void fail(const char* what) {
        const std::string reason = std::strerror(errno);
        ::close(fd_);
        throw std::runtime_error(db_ + ": cannot " + what + " the runner lock (" + reason + ")");
    }
    std::string db_;
    int fd_ = -1;
};

/// A loaded scene's checks that need its content: warm-up that leaves no frame (a recording's
/// frames are known only now), and two entries whose scenes are one (two recordings with the
/// same bytes): stored by content, the second name's cells would land under the first's.
void check_loaded_scene(const Experiment& e, std::size_t index, const Recording& recording, const std::string& hash,
                        std::map<std::string, std::size_t>& by_hash, const std::string& source) {
    const SceneSpec& scene = e.scenes[index];
    const std::string file = scene.path.empty() ? "" : ", " + scene.path;
    try {
        check_warmup(e.warmup_frames, recording.frames.size());
    } catch (const InputError& err) {
        throw InputError(source + ": warmup_frames: " + err.what() + " (" + scene.where + ": scene " + scene.name +
                         file + ")");
    }
    const auto [it, added] = by_hash.emplace(hash, index);
    if (!added && it->second != index)
        throw InputError(source + ": " + scene.where + ": the same scene as " + e.scenes[it->second].where + " (\"" +
                         e.scenes[it->second].name + "\" and \"" + scene.name + "\" have identical content" + file +
                         "): their cells would be stored as one; make them differ or drop one");
}

constexpr auto kResampleWait = std::chrono::milliseconds(200);

/// The machine's state before a cell, used: while the calibration loop or the memory probe runs
/// more than kSlowCalibration slower than the median of the run's samples so far (another process
/// on the core or on the caches, a throttled clock), wait and sample again, up to kResampleLimit
/// times and while `allowance` lasts; the cell is then measured, and flagged afterwards if it was
/// still slow (ResultStore::flag_slow_cells).
MachineState settled_machine_state(std::vector<double>& samples, std::vector<double>& memory,
                                   std::chrono::nanoseconds allowance) {
    constexpr int kResampleLimit = 5;
    constexpr std::size_t kSamplesBeforeJudging = 5;
    MachineState state = sample_machine_state();
    while (samples.size() >= kSamplesBeforeJudging && state.resampled < kResampleLimit && allowance >= kResampleWait &&
           (state.calibration_ns > (1 + kSlowCalibration) * median(samples) ||
            state.memory_ns > (1 + kSlowCalibration) * median(memory))) {
        std::this_thread::sleep_for(kResampleWait);
        allowance -= kResampleWait;
        const int resampled = state.resampled + 1;
        state = sample_machine_state();
        state.resampled = resampled;
    }
    samples.push_back(state.calibration_ns);
    memory.push_back(state.memory_ns);
    return state;
}

/// Runs one list of cells, skipping those stored; shared by the planned repetitions and the rounds
/// added where the interval over repetitions is wide.
class CellRunner {
public:
    CellRunner(const Experiment& e, const std::string& source, ResultStore& store, RunOutcome& out,
               std::function<void(SimulationResult&)> timing, std::function<void()> after_cell)
        : e_(e),
          source_(source),
          store_(store),
          out_(out),
          experiment_(store.experiment_id(e)),
          timing_(std::move(timing)),
          after_cell_(std::move(after_cell)) {
        sim_.verify = e.verify;
        sim_.warmup_frames = e.warmup_frames;
        if (e.cold_cache) sim_.cold_cache = std::make_shared<const CacheSweep>(cold_sweep_bytes());
    }

    void run(const std::vector<Cell>& cells, const std::set<std::string>& done, std::size_t todo,
             const RunProgress& progress) {
        for (const Cell& c : cells) {
            // Another runner on the same database may have stored the cell since we looked.
            if (done.count(c.key) || store_.cell_done(out_.run, c.key)) continue;
            const SceneSpec& scene = e_.scenes[c.scene];
            const ConfigSpec& config = e_.configs[c.config];
            const LoadedScene& loaded = load(c.scene);
            if (progress)
                progress(out_.ran, todo,
                         scene.name + "  " + config_label(config) + "  rep " + std::to_string(c.repetition));
            SimulationResult res;
            MachineState state;
            try {
                // Waiting may take at most 5% of the time spent measuring: on a host whose caches
                // other tenants share, the slow state can outlast any wait.
                state = settled_machine_state(calibration_samples_, memory_samples_, measured_ / 20 - waited_);
                waited_ += state.resampled * kResampleWait;
                const auto start = std::chrono::steady_clock::now();
                res = simulate(loaded.recording(), find_structure(config.structure), config.params, sim_);
                measured_ += std::chrono::steady_clock::now() - start;
                if (timing_) timing_(res);
            } catch (const InputError& err) {
                throw InputError(source_ + ": scene " + scene.name + ": " + err.what());
            }
            out_.mismatches += res.mismatches();
            out_.resampled += state.resampled > 0;
            store_.store_cell(out_.run, experiment_, c, scene, loaded.recording(), loaded.hash, res, state);
            ++out_.ran;
            after_cell_();
        }
    }

private:
    /// A scene as loaded: generated, imported or read once per run and kept, since a repetition
    /// visits the scenes' cells interleaved. The scenes of one recording (the phases of one entry,
    /// recording_key) share it: generated once and held once. Each scene keeps its own META (its
    /// window) and hash, as if loaded alone.
    struct LoadedScene {
        std::shared_ptr<Recording> shared;
        std::string meta;  ///< the scene's META: the recording's with its window marked
        std::string hash;  ///< recording_hash of the recording with `meta`
        /// The recording with this scene's window; valid until another scene's is asked for.
        const Recording& recording() const {
            shared->meta = meta;
            return *shared;
        }
    };
    /// A recording shared by scenes, with its META as generated (no window).
    struct SharedRecording {
        std::shared_ptr<Recording> recording;
        std::string meta;
    };

    const LoadedScene& load(std::size_t index) {
        const auto it = loaded_.find(index);
        if (it != loaded_.end()) return it->second;
        const SceneSpec& scene = e_.scenes[index];
        LoadedScene l;
        try {
            const std::string key = recording_key(scene);
            auto shared = recordings_.find(key);
            if (shared == recordings_.end()) {
                auto recording = std::make_shared<Recording>(load_scene_frames(scene));
                std::string meta = recording->meta;
                shared = recordings_.emplace(key, SharedRecording{std::move(recording), std::move(meta)}).first;
                ++out_.recordings;
            }
            l.shared = shared->second.recording;
            l.shared->meta = shared->second.meta;
            l.meta = measured_meta(scene, *l.shared);
        } catch (const InputError& err) {
            throw InputError(source_ + ": scene " + scene.name + ": " + err.what());
        }
        l.hash = recording_hash(l.recording());
        check_loaded_scene(e_, index, l.recording(), l.hash, scene_by_hash_, source_);
        return loaded_.emplace(index, std::move(l)).first->second;
    }

    const Experiment& e_;
    const std::string& source_;
    ResultStore& store_;
    RunOutcome& out_;
    std::int64_t experiment_;
    std::function<void(SimulationResult&)> timing_;
    std::function<void()> after_cell_;
    SimulationOptions sim_;
    std::map<std::size_t, LoadedScene> loaded_;
    std::map<std::string, SharedRecording> recordings_;  ///< by recording_key
    std::map<std::string, std::size_t> scene_by_hash_;
    std::vector<double> calibration_samples_, memory_samples_;
    std::chrono::nanoseconds measured_{0}, waited_{0};
};

/// Repetition `round` of the (scene, configuration) pairs of `plan` whose first `round`
/// repetitions are all stored and whose ray-cast or update interval over them is wide: a 95%
/// half-width above e.repeat_interval of the median (wide_interval).
std::vector<Cell> wide_interval_cells(const Experiment& e, const std::vector<Cell>& plan,
                                      const std::map<std::string, std::pair<double, double>>& medians,
                                      std::uint32_t round) {
    std::vector<std::pair<std::size_t, std::size_t>> pairs;
    for (const Cell& c : plan) {
        if (c.repetition != 0) continue;
        std::vector<double> cast, update;
        for (std::uint32_t r = 0; r < round; ++r) {
            const auto it = medians.find(cell_key(e, c.scene, c.config, r));
            if (it == medians.end()) break;
            cast.push_back(it->second.first);
            update.push_back(it->second.second);
        }
        if (cast.size() != round) continue;
        if (wide_interval(cast, e.repeat_interval) || wide_interval(update, e.repeat_interval))
            pairs.emplace_back(c.scene, c.config);
    }
    return repetition_cells(e, round, pairs);
}

}  // namespace

bool wide_interval(const std::vector<double>& medians, double limit) {
    return repetition_interval(medians).relative_half_width() > limit;
}

double relative_range(const std::vector<double>& values) {
    if (values.size() < 2) return 0;
    const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
    const double median = spread_of(values).median;
    return median > 0 ? (*hi - *lo) / median : 0;
}

RunOutcome run_experiment(const Experiment& e, const std::string& source, const RunOptions& options,
                          const RunProgress& progress) {
    const std::vector<Cell> plan = shard_plan(e, options.shard_k, options.shard_n);
    ResultStore store(options.db);
    const std::string shard =
        options.shard_n == 1 ? "" : std::to_string(options.shard_k) + "/" + std::to_string(options.shard_n);
    RunOutcome out;
    out.planned = plan.size();
    if (options.run_id) {
        const std::optional<std::string> binary = store.run_binary(options.run_id);
        if (!binary) throw InputError("--run " + std::to_string(options.run_id) + ": no such run in " + options.db);
        if (*binary != this_binary().name)
            throw InputError("--run " + std::to_string(options.run_id) + ": a run of " + *binary + ", not of " +
                             this_binary().name + " (a run is resumed by the program that began it)");
        out.run = options.run_id;
    } else {
        out.run = store.resume_or_begin_run(e, RunInfo::current(e.threads, shard, e), options.new_run);
    }
    // After choosing the run, so a runner that waited resumes the run it would have shared.
    const RunnerLock lock(options.db, options.on_wait);
    const std::set<std::string> done = store.finished_cells(out.run);
    for (const Cell& c : plan) out.done_before += done.count(c.key) != 0;
    const std::size_t todo = plan.size() - out.done_before;

    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, e.threads);
    // The run's machine: cache sizes and each structure's calibration (at its first configuration,
    // with the run's threads), measured before the run's first cell and again every
    // calibration_spacing between cells.
    CalibratedStructures structures;
    for (const ConfigSpec& c : e.configs)
        if (std::none_of(structures.begin(), structures.end(), [&](const auto& s) { return s.first == c.structure; }))
            structures.emplace_back(c.structure, c.params);
    out.calibrations += record_machine(store.db(), out.run, structures);
    auto last_pass = std::chrono::steady_clock::now();
    const auto recalibrate = [&] {
        if (std::chrono::steady_clock::now() - last_pass < options.calibration_spacing) return;
        add_calibration_pass(store.db(), out.run, structures);
        ++out.calibrations;
        last_pass = std::chrono::steady_clock::now();
    };
    CellRunner runner(e, source, store, out, options.timing, recalibrate);
    runner.run(plan, done, todo, progress);
    // Rounds of repetitions where the interval over the stored ones is wide, each judged on what
    // is stored. They sharpen the cell's median and its fastest frames, not its stated interval,
    // which rests on the planned repetitions (store_cell_interval): stopping where two repetitions
    // happen to agree would make that interval cover less than 95%.
    for (std::uint32_t round = e.repetitions; round < e.max_repetitions; ++round) {
        const std::vector<Cell> extra = wide_interval_cells(e, plan, store.cell_medians(out.run), round);
        if (extra.empty()) break;
        const std::set<std::string> now = store.finished_cells(out.run);
        std::size_t left = 0;
        for (const Cell& c : extra) left += now.count(c.key) == 0;
        out.added += extra.size();
        runner.run(extra, now, out.ran + left, progress);
    }
    out.slow = store.flag_slow_cells(out.run);
    const std::set<std::string> now_done = store.finished_cells(out.run);
    out.finished = std::all_of(plan.begin(), plan.end(), [&](const Cell& c) { return now_done.count(c.key) != 0; });
    if (out.finished) store.finish_run(out.run);
    return out;
}

}  // namespace rcb
