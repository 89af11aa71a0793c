// Build speed of the linear BVH: a generated scene (irreg-xl by default: 1 000 000 objects) is
// built from scratch (build(): the slot table, then the tree) and rebuilt after 1% of the objects
// moved (commit(): the tree only, what every frame pays), `repeats` times for 1 and 2 build threads,
// alternating in one process so that both see the same machine. Prints medians with min and max,
// objects per second, the median time of each step of the rebuild (LinearBvh::last_phases) and the
// two-thread speed-up. Pin it: `taskset -c 0 … --threads 1`, `taskset -c 0,1 …`.
//
//   build/bench/lbvh_build [PRESET] [REPEATS]      PRESET: irreg-xl, clusters-xl, … (default irreg-xl)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <unordered_map>
#include <vector>

#include "bench/bench_util.h"
#include "core/error.h"
#include "core/generators.h"
#include "core/structures/linear_bvh.h"

namespace {

using namespace rcb;
using bench::Clock;
using bench::median;
using bench::ms_since;

struct Series {
    std::vector<double> build, rebuild, codes, sort, tree;
};

void print(const char* what, const std::vector<double>& t, std::size_t n) {
    std::printf("  %-9s median %8.2f ms  (min %.2f, max %.2f)  %6.2f M objects/s\n", what, median(t),
                *std::min_element(t.begin(), t.end()), *std::max_element(t.begin(), t.end()),
                double(n) / median(t) / 1e3);
}

int run(int argc, char** argv) {
    if (argc > 3) throw InputError("usage: lbvh_build [PRESET] [REPEATS]");
    const std::string preset = argc >= 2 ? argv[1] : "irreg-xl";
    const int repeats = argc == 3 ? std::stoi(argv[2]) : 5;
    if (repeats < 1 || repeats > 1000) throw InputError("REPEATS: from 1 to 1000");
    SceneSettings settings = preset_settings(preset);
    settings.frames = 1;
    settings.rays.per_frame = 1;
    settings.dynamics.insert_share = settings.dynamics.remove_share = 0;  // 1% moves
    const Recording rec = generate_scene(settings);
    const std::vector<Object>& objects = rec.initial;
    const std::vector<Object>& moves = rec.frames.at(0).moves;
    std::unordered_map<Uid, Aabb> first_box;
    for (const Object& o : objects) first_box.emplace(o.uid, o.box);
    std::vector<Object> back;  // the moved objects' first boxes: every other rebuild moves them back
    for (const Object& m : moves) back.push_back({m.uid, first_box.at(m.uid)});
    const std::size_t n = objects.size();
    std::printf("%s: %zu objects, %zu moves per rebuild, %d repeats\n", preset.c_str(), n, moves.size(), repeats);

    LinearBvh one(LinearBvh::Params{.threads = 1}), two(LinearBvh::Params{.threads = 2});
    Series s[2];
    for (int r = 0; r < repeats; ++r)
        for (int k = 0; k < 2; ++k) {
            LinearBvh& t = k == 0 ? one : two;
            Clock::time_point t0 = Clock::now();
            t.build(objects);
            s[k].build.push_back(ms_since(t0));
            for (const Object& m : r % 2 ? back : moves) t.move(m);
            t0 = Clock::now();
            t.commit();
            s[k].rebuild.push_back(ms_since(t0));
            const LinearBvh::Phases& p = t.last_phases();
            s[k].codes.push_back(p.codes), s[k].sort.push_back(p.sort), s[k].tree.push_back(p.tree);
        }
    if (!(one.nodes() == two.nodes())) throw std::logic_error("1 and 2 threads built different trees");
    for (int k = 0; k < 2; ++k) {
        std::printf("threads=%d\n", k + 1);
        print("build", s[k].build, n);
        print("rebuild", s[k].rebuild, n);
        std::printf("  rebuild steps (median ms): codes %.2f, sort %.2f, tree %.2f\n", median(s[k].codes),
                    median(s[k].sort), median(s[k].tree));
    }
    std::printf("speed-up of 2 threads: build %.2fx, rebuild %.2fx\n", median(s[0].build) / median(s[1].build),
                median(s[0].rebuild) / median(s[1].rebuild));
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    try {
        return run(argc, argv);
    } catch (const rcb::InputError& e) {
        std::fprintf(stderr, "lbvh_build: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "lbvh_build: %s\n", e.what());
        return 1;
    }
}
