// Where the wide BVH's update goes on a recording (a physics scene from `rcbench scene gen`, or one
// generated here): the recording's frames are applied as the simulator applies them (removes,
// inserts, moves, commit), with the update cut into phases timed apart, in the thread's CPU time:
//
//   lookup    the uid → slot lookups of the frame's moves, timed on a copy of the index in the
//             tree's own layout beside a hash map's, in the moves' order (the tree's lookup is
//             inside its move, so the copy stands for it; the map is what the index replaced)
//   moves     the frame's move() calls (each checks its uid and queues the move) and the queue's
//             application: lookup, lane rewrite, and the reinsertions with their leaf splits;
//             with timed_moves=1 each move is applied at once and timed apart (TSC cycles), its
//             cycles going to `rewrite` or to `reinsert` by whether it reinserted (without the
//             queue's prefetching)
//             (with threads=2 the inserts are queued too and applied first in this phase)
//   refit     the bottom-up refit of the changed blocks (prepare(), which commit would run)
//   rebuild   the rest of commit(): the rebuild trigger and the progressive rebuild's step
//
// with counts per frame: moves, reinserts, leaf splits, blocks refitted, lanes rewritten by the
// refit, rebuild work (build units) and rebuilds. Prints the medians over the measured frames,
// then every frame's row with rows=1. The times are one run's; pin it, repeat it, and read
// instruction shares with callgrind (docs/structures.md, wbvh):
//
//   build/bench/wbvh_update SCENE.rec [key=value …]
//   build/bench/wbvh_update generator=brownian objects=10000 frames=40 seed=2 [key=value …]
//     bench keys: frames=N (the first N frames; all by default), warmup=W (3; not in the medians),
//                 timed_moves=0|1 (0), rows=0|1 (0), generator (`kind`, its old name,
//                 still works), objects, seed (a generated scene instead of a file)
//     any other key is a wbvh parameter, e.g. reinsert=false, threads=2 (the update's threads)
#include <algorithm>
#include <cstdio>
#include <ctime>
#include <string>
#include <unordered_map>
#include <vector>

#include <x86intrin.h>

#include "bench/bench_util.h"
#include "accel/bvh/wide_bvh.h"
#include "accel/interface/params.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"

namespace {

using namespace rcb;

double cpu_ms() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return double(t.tv_sec) * 1e3 + double(t.tv_nsec) * 1e-6;
}

/// One frame's phases (ms of thread CPU time; cycles for the per-move split) and counts.
struct FrameRow {
    double lookup_flat = 0, lookup_map = 0, removes_inserts = 0, moves = 0, refit = 0, rebuild = 0;
    double rewrite_cycles = 0, reinsert_cycles = 0;
    std::uint64_t moves_n = 0, reinserts = 0, splits = 0, refit_blocks = 0, refit_lanes = 0, rebuild_work = 0,
                  rebuilds = 0;
    double total() const { return removes_inserts + moves + refit + rebuild; }
};

struct Settings {
    std::string path;
    SceneSettings scene;
    std::uint32_t frames = 0, warmup = 3;
    bool timed_moves = false, rows = false;
    nlohmann::json params = nlohmann::json::object();
};

Settings parse(int argc, char** argv) {
    Settings s;
    s.scene.generator.clear();
    s.scene.objects = 10000;
    s.scene.frames = 40;
    s.scene.seed = 1;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg.find('=') == std::string::npos) {
            if (!s.path.empty()) throw InputError("usage: wbvh_update [SCENE.rec] [key=value …]");
            s.path = arg;
            continue;
        }
        const auto [key, value] = parse_key_value(arg);
        if (key == "frames")
            s.frames = value.get<std::uint32_t>();
        else if (key == "warmup")
            s.warmup = value.get<std::uint32_t>();
        else if (key == "timed_moves")
            s.timed_moves = value.get<int>() != 0;
        else if (key == "rows")
            s.rows = value.get<int>() != 0;
        else if (key == "generator" || key == "kind")
            s.scene.generator = value.get<std::string>();
        else if (key == "objects")
            s.scene.objects = value.get<std::uint32_t>();
        else if (key == "seed")
            s.scene.seed = value.get<std::uint64_t>();
        else
            s.params[key] = value;
    }
    if (s.path.empty() == s.scene.generator.empty())
        throw InputError("give a recording file or generator=GENERATOR, not both");
    if (s.frames != 0 && s.path.empty()) s.scene.frames = s.frames;
    s.scene.rays.per_frame = 0;
    return s;
}

/// Times the lookups of `frame`'s moves in the flat index and in a hash map of the same uids.
void time_lookups(const Frame& frame, const WideBvhIndex& flat, const std::unordered_map<Uid, std::uint32_t>& map,
                  FrameRow& row) {
    std::uint64_t sink = 0;
    double c0 = cpu_ms();
    for (const Object& o : frame.moves) sink += flat.find(o.uid);
    row.lookup_flat = cpu_ms() - c0;
    c0 = cpu_ms();
    for (const Object& o : frame.moves) sink += map.find(o.uid)->second;
    row.lookup_map = cpu_ms() - c0;
    if (sink == 1) std::printf(" ");  // keeps the loops
}

/// Applies one frame to `tree`, phase by phase.
FrameRow apply(WideBvh& tree, const Frame& frame, bool timed_moves) {
    FrameRow row;
    const WideBvh::UpdateCounts before = tree.update_counts();
    double c0 = cpu_ms();
    for (Uid uid : frame.removes) tree.remove(uid);
    for (const Object& o : frame.inserts) tree.insert(o);
    row.removes_inserts = cpu_ms() - c0;
    c0 = cpu_ms();
    if (timed_moves) {
        for (const Object& o : frame.moves) {
            const std::uint64_t reinserts = tree.update_counts().reinserts;
            const std::uint64_t t = __rdtsc();
            tree.move(o);
            tree.flush_moves();
            const double cycles = double(__rdtsc() - t);
            (tree.update_counts().reinserts != reinserts ? row.reinsert_cycles : row.rewrite_cycles) += cycles;
        }
    } else {
        for (const Object& o : frame.moves) tree.move(o);
        tree.flush_moves();
    }
    row.moves = cpu_ms() - c0;
    c0 = cpu_ms();
    tree.prepare();  // the refit that commit() would run first
    row.refit = cpu_ms() - c0;
    c0 = cpu_ms();
    tree.commit();
    row.rebuild = cpu_ms() - c0;
    const WideBvh::UpdateCounts after = tree.update_counts();
    row.moves_n = frame.moves.size();
    row.reinserts = after.reinserts - before.reinserts;
    row.splits = after.splits - before.splits;
    row.refit_blocks = after.refit_blocks - before.refit_blocks;
    row.refit_lanes = after.refit_lanes - before.refit_lanes;
    row.rebuild_work = after.rebuild_work - before.rebuild_work;
    row.rebuilds = after.rebuilds - before.rebuilds;
    return row;
}

template <class F>
double median_of(const std::vector<FrameRow>& rows, F f) {
    std::vector<double> v;
    for (const FrameRow& r : rows) v.push_back(double(f(r)));
    return v.empty() ? 0.0 : median(v);
}

void print_row(const char* label, const FrameRow& r) {
    std::printf("%8s %8.4f %8.4f %8.4f %8.4f %8.4f %8.4f %8.4f | %6llu %6llu %6llu %6llu %6llu %9llu %3llu\n", label,
                r.lookup_flat, r.lookup_map, r.removes_inserts, r.moves, r.refit, r.rebuild, r.total(),
                (unsigned long long)r.moves_n, (unsigned long long)r.reinserts, (unsigned long long)r.splits,
                (unsigned long long)r.refit_blocks, (unsigned long long)r.refit_lanes,
                (unsigned long long)r.rebuild_work, (unsigned long long)r.rebuilds);
}

int run(int argc, char** argv) {
    const Settings s = parse(argc, argv);
    const WideBvh::Params p = params_from_json<WideBvh::Params>(s.params, "params", "wbvh");
    Recording rec = s.path.empty() ? generate_scene(s.scene) : read_recording(s.path);
    if (s.frames != 0 && rec.frames.size() > s.frames) rec.frames.resize(s.frames);
    std::printf("%s: %zu objects, %zu frames (the first %u warm up)\nparams %s\n",
                s.path.empty() ? s.scene.generator.c_str() : s.path.c_str(), rec.initial.size(), rec.frames.size(),
                s.warmup, params_to_json(p).dump().c_str());

    WideBvh tree(p);
    tree.build(rec.initial);
    // The lookups' copies: the flat index and a hash map over the live uids (slots are not used).
    WideBvhIndex flat;
    std::unordered_map<Uid, std::uint32_t> map;
    Uid max_uid = 0;
    for (const Object& o : rec.initial) max_uid = std::max(max_uid, o.uid);
    flat.reserve(rec.initial.size(), max_uid);
    for (const Object& o : rec.initial) flat.set(o.uid, o.uid), map[o.uid] = o.uid;

    std::vector<FrameRow> measured;
    std::printf("%8s %8s %8s %8s %8s %8s %8s %8s | %6s %6s %6s %6s %6s %9s %3s\n", "frame", "lk_flat", "lk_map",
                "rem+ins", "moves", "refit", "rebuild", "update", "moves", "reins", "splits", "blocks", "lanes",
                "rb_work", "rb");
    for (std::size_t f = 0; f < rec.frames.size(); ++f) {
        const Frame& frame = rec.frames[f];
        for (Uid uid : frame.removes) flat.erase(uid), map.erase(uid);
        for (const Object& o : frame.inserts) flat.set(o.uid, o.uid), map[o.uid] = o.uid;
        FrameRow row = apply(tree, frame, s.timed_moves);
        time_lookups(frame, flat, map, row);
        if (s.rows) print_row(std::to_string(f + 1).c_str(), row);
        if (f >= s.warmup) measured.push_back(row);
    }
    tree.check();
    FrameRow med;
    med.lookup_flat = median_of(measured, [](const FrameRow& r) { return r.lookup_flat; });
    med.lookup_map = median_of(measured, [](const FrameRow& r) { return r.lookup_map; });
    med.removes_inserts = median_of(measured, [](const FrameRow& r) { return r.removes_inserts; });
    med.moves = median_of(measured, [](const FrameRow& r) { return r.moves; });
    med.refit = median_of(measured, [](const FrameRow& r) { return r.refit; });
    med.rebuild = median_of(measured, [](const FrameRow& r) { return r.rebuild; });
    med.moves_n = std::uint64_t(median_of(measured, [](const FrameRow& r) { return r.moves_n; }));
    med.reinserts = std::uint64_t(median_of(measured, [](const FrameRow& r) { return r.reinserts; }));
    med.splits = std::uint64_t(median_of(measured, [](const FrameRow& r) { return r.splits; }));
    med.refit_blocks = std::uint64_t(median_of(measured, [](const FrameRow& r) { return r.refit_blocks; }));
    med.refit_lanes = std::uint64_t(median_of(measured, [](const FrameRow& r) { return r.refit_lanes; }));
    med.rebuild_work = std::uint64_t(median_of(measured, [](const FrameRow& r) { return r.rebuild_work; }));
    print_row("median", med);
    FrameRow sum;
    for (const FrameRow& r : measured) {
        sum.lookup_flat += r.lookup_flat, sum.lookup_map += r.lookup_map, sum.removes_inserts += r.removes_inserts;
        sum.moves += r.moves, sum.refit += r.refit, sum.rebuild += r.rebuild;
        sum.rewrite_cycles += r.rewrite_cycles, sum.reinsert_cycles += r.reinsert_cycles;
        sum.moves_n += r.moves_n, sum.reinserts += r.reinserts, sum.splits += r.splits;
        sum.refit_blocks += r.refit_blocks, sum.refit_lanes += r.refit_lanes, sum.rebuild_work += r.rebuild_work;
        sum.rebuilds += r.rebuilds;
    }
    print_row("total", sum);
    const double t = sum.total() > 0 ? sum.total() : 1;
    std::printf(
        "share of the update over %zu frames: moves %.1f%%, refit %.1f%%, rebuild %.1f%%, removes and "
        "inserts %.1f%%; moves that reinserted %.2f%%\n",
        measured.size(), 100 * sum.moves / t, 100 * sum.refit / t, 100 * sum.rebuild / t, 100 * sum.removes_inserts / t,
        sum.moves_n ? 100.0 * double(sum.reinserts) / double(sum.moves_n) : 0.0);
    // Rebuild frames apart: a median over frames does not see them, and at 10^6 objects one
    // frame's whole rebuild can outweigh the rest of a short run.
    double rebuild_frames = 0, rebuild_frames_update = 0;
    for (const FrameRow& r : measured)
        if (r.rebuilds > 0 || r.rebuild_work > 0) ++rebuild_frames, rebuild_frames_update += r.total();
    std::printf("frames with rebuild work: %.0f of %zu, %.1f%% of the update; update arena steps (threads=%d): %llu\n",
                rebuild_frames, measured.size(), 100 * rebuild_frames_update / t, p.threads,
                (unsigned long long)tree.parallel_steps());
    if (s.timed_moves) {
        const double c = std::max(1.0, sum.rewrite_cycles + sum.reinsert_cycles);
        std::printf(
            "moves by kind (TSC cycles, with the timer's own): rewrite %.1f%% (%.0f per move), reinsert "
            "%.1f%% (%.0f per move)\n",
            100 * sum.rewrite_cycles / c,
            sum.rewrite_cycles / double(std::max<std::uint64_t>(1, sum.moves_n - sum.reinserts)),
            100 * sum.reinsert_cycles / c, sum.reinsert_cycles / double(std::max<std::uint64_t>(1, sum.reinserts)));
    }
    std::printf("stats %s\n", tree.stats().dump().c_str());
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("wbvh_update", run, argc, argv); }
