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
#include <set>

#include "core/base/error.h"
#include "core/accel/registry.h"
#include "core/sim/simulator.h"
#include "runner/calibration.h"
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

MachineState sample_machine_state() {
    MachineState m;
    m.load_1m = -1;
    if (std::ifstream in("/proc/loadavg"); in) in >> m.load_1m;
    if (!std::isfinite(m.load_1m)) m.load_1m = -1;
    std::vector<double> passes;
    for (int pass = 0; pass < 3; ++pass) {
        const auto start = std::chrono::steady_clock::now();
        std::uint64_t x = 0x9e3779b97f4a7c15ULL + std::uint64_t(pass);
        for (int i = 0; i < 750'000; ++i) x = x * 6364136223846793005ULL + 1442695040888963407ULL;
        // The result is used, so the chain cannot be folded away.
        volatile std::uint64_t sink = x;
        (void)sink;
        passes.push_back(double(
            std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() - start).count()));
    }
    m.calibration_ns = spread_of(passes).median;
    return m;
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

}  // namespace

RunOutcome run_experiment(const Experiment& e, const std::string& source, const RunOptions& options,
                          const RunProgress& progress) {
    const std::vector<Cell> plan = shard_plan(e, options.shard_k, options.shard_n);
    ResultStore store(options.db);
    const std::string shard =
        options.shard_n == 1 ? "" : std::to_string(options.shard_k) + "/" + std::to_string(options.shard_n);
    RunOutcome out;
    out.planned = plan.size();
    if (options.run_id) {
        if (!store.run_exists(options.run_id))
            throw InputError("--run " + std::to_string(options.run_id) + ": no such run in " + options.db);
        out.run = options.run_id;
    } else {
        out.run = store.resume_or_begin_run(e, RunInfo::current(e.threads, shard, e), options.new_run);
    }
    // After choosing the run, so a runner that waited resumes the run it would have shared.
    const RunnerLock lock(options.db, options.on_wait);
    const std::int64_t experiment = store.experiment_id(e);
    const std::set<std::string> done = store.finished_cells(out.run);
    for (const Cell& c : plan) out.done_before += done.count(c.key) != 0;
    const std::size_t todo = plan.size() - out.done_before;

    tbb::global_control threads(tbb::global_control::max_allowed_parallelism, e.threads);
    // The run's machine: cache sizes and each structure's calibration (at its first configuration,
    // with the run's threads), measured once per run before its first cell.
    std::vector<std::pair<std::string, nlohmann::json>> structures;
    for (const ConfigSpec& c : e.configs)
        if (std::none_of(structures.begin(), structures.end(), [&](const auto& s) { return s.first == c.structure; }))
            structures.emplace_back(c.structure, c.params);
    record_machine(store.db(), out.run, structures);
    SimulationOptions sim;
    sim.verify = e.verify;
    sim.warmup_frames = e.warmup_frames;
    // Cells are repetition-major; consecutive cells of a scene share one load.
    std::size_t loaded = SIZE_MAX;
    Recording recording;
    std::string scene_hash;
    std::map<std::string, std::size_t> scene_by_hash;
    for (const Cell& c : plan) {
        // Another runner on the same database may have stored the cell since we looked.
        if (done.count(c.key) || store.cell_done(out.run, c.key)) continue;
        const SceneSpec& scene = e.scenes[c.scene];
        const ConfigSpec& config = e.configs[c.config];
        if (loaded != c.scene) {
            try {
                recording = load_scene(scene);
            } catch (const InputError& err) {
                throw InputError(source + ": scene " + scene.name + ": " + err.what());
            }
            scene_hash = recording_hash(recording);
            loaded = c.scene;
            check_loaded_scene(e, c.scene, recording, scene_hash, scene_by_hash, source);
        }
        if (progress)
            progress(out.ran, todo, scene.name + "  " + config_label(config) + "  rep " + std::to_string(c.repetition));
        SimulationResult res;
        MachineState state;
        try {
            state = sample_machine_state();
            res = simulate(recording, find_structure(config.structure), config.params, sim);
        } catch (const InputError& err) {
            throw InputError(source + ": scene " + scene.name + ": " + err.what());
        }
        out.mismatches += res.mismatches();
        store.store_cell(out.run, experiment, c, scene, recording, scene_hash, res, state);
        ++out.ran;
    }
    out.slow = store.flag_slow_cells(out.run);
    const std::set<std::string> now_done = store.finished_cells(out.run);
    out.finished = std::all_of(plan.begin(), plan.end(), [&](const Cell& c) { return now_done.count(c.key) != 0; });
    if (out.finished) store.finish_run(out.run);
    return out;
}

}  // namespace rcb
