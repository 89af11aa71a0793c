// Build speed of the linear BVH: a generated scene (irreg-xl by default: 1 000 000 objects) is
// built from scratch (build(): the slot table, then the tree) and rebuilt twice, after 1% of the
// objects moved and after they moved back (commit(): the tree only, what every frame pays),
// `repeats` times for 1 and 2 build threads and for 1 thread with the radix sort only
// (coherent_sort off), alternating in one process so that all see the same machine. Given a scene
// recording instead (`rcbench scene gen` or `rcbench scene import`), each repeat builds its first
// frame and rebuilds after each of its frames' changes (removes, inserts, moves), as `rcbench
// simulate` does. Prints medians with min and max, objects per second, the median time of each step
// of the rebuild (LinearBvh::last_phases), how many rebuilds sorted from the last order, and the
// two-thread speed-up. Pin it: `taskset -c 0 …` for one core, `taskset -c 0,1 …` for two.
//
//   build/bench/lbvh_build [PRESET | SCENE.rcbscene] [REPEATS]   PRESET: irreg-xl, clusters-xl, …
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <unordered_map>
#include <vector>

#include "bench/bench_util.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "accel/bvh/linear_bvh.h"
#include "core/scene/recording_io.h"

namespace {

using namespace rcb;
using bench::Clock;
using bench::ms_since;

struct Series {
    std::vector<double> build, rebuild, codes, sort, tree;
};

void print(const char* what, const std::vector<double>& t, std::size_t n) {
    std::printf("  %-9s median %8.2f ms  (min %.2f, max %.2f)  %6.2f M objects/s\n", what, median(t),
                *std::min_element(t.begin(), t.end()), *std::max_element(t.begin(), t.end()),
                double(n) / median(t) / 1e3);
}

/// The preset's first frame, and two frames of changes: 1% of the objects move, then move back.
Recording preset_rebuilds(const std::string& preset) {
    SceneSettings settings = preset_settings(preset);
    settings.frames = 1;
    settings.rays.per_frame = 1;
    settings.dynamics.insert_share = settings.dynamics.remove_share = 0;  // 1% moves
    Recording rec = generate_scene(settings);
    std::unordered_map<Uid, Aabb> first_box;
    for (const Object& o : rec.initial) first_box.emplace(o.uid, o.box);
    Frame back;  // the moved objects' first boxes: the second rebuild moves them back
    for (const Object& m : rec.frames.at(0).moves) back.moves.push_back({m.uid, first_box.at(m.uid)});
    rec.frames.push_back(std::move(back));
    return rec;
}

int run(int argc, char** argv) {
    if (argc > 3) throw InputError("usage: lbvh_build [PRESET | SCENE.rcbscene] [REPEATS]");
    const std::string preset = argc >= 2 ? argv[1] : "irreg-xl";
    const int repeats = argc == 3 ? int(bench::count_arg(argv[2], "REPEATS", 1, 1000)) : 5;
    const Recording rec = std::filesystem::is_regular_file(preset) ? read_recording(preset) : preset_rebuilds(preset);
    const std::vector<Object>& objects = rec.initial;
    const std::size_t n = objects.size();
    std::printf("%s: %zu objects, %zu rebuilds per repeat (%zu changes in the first), %d repeats\n", preset.c_str(), n,
                rec.frames.size(), rec.frames.empty() ? 0 : rec.frames[0].change_count(), repeats);

    LinearBvh one(LinearBvh::Params{.threads = 1}), two(LinearBvh::Params{.threads = 2}),
        radix(LinearBvh::Params{.threads = 1, .coherent_sort = false});
    LinearBvh* trees[3] = {&one, &two, &radix};
    const char* names[3] = {"threads=1", "threads=2", "threads=1, radix sort only"};
    Series s[3];
    int resorted[3] = {};
    for (int r = 0; r < repeats; ++r)
        for (int k = 0; k < 3; ++k) {
            LinearBvh& t = *trees[k];
            Clock::time_point t0 = Clock::now();
            t.build(objects);
            s[k].build.push_back(ms_since(t0));
            for (const Frame& frame : rec.frames) {
                for (Uid uid : frame.removes) t.remove(uid);
                for (const Object& o : frame.inserts) t.insert(o);
                for (const Object& m : frame.moves) t.move(m);
                t0 = Clock::now();
                t.commit();
                s[k].rebuild.push_back(ms_since(t0));
                const LinearBvh::Phases& p = t.last_phases();
                s[k].codes.push_back(p.codes), s[k].sort.push_back(p.sort), s[k].tree.push_back(p.tree);
                resorted[k] += t.last_resorted();
            }
        }
    if (!(one.nodes() == two.nodes()) || !(one.nodes() == radix.nodes()))
        throw std::logic_error("the configurations built different trees");
    for (int k = 0; k < 3; ++k) {
        std::printf("%s\n", names[k]);
        print("build", s[k].build, n);
        print("rebuild", s[k].rebuild, n);
        std::printf(
            "  rebuild steps (median ms): codes %.2f, sort %.2f, tree %.2f; %d of %zu sorted from the last order\n",
            median(s[k].codes), median(s[k].sort), median(s[k].tree), resorted[k], s[k].rebuild.size());
    }
    std::printf("speed-up of 2 threads: build %.2fx, rebuild %.2fx\n", median(s[0].build) / median(s[1].build),
                median(s[0].rebuild) / median(s[1].rebuild));
    return 0;
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("lbvh_build", run, argc, argv); }
