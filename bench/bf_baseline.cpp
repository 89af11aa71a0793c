// Brute force against the plainest fast loop over the same boxes: rcbench's `bf` casts a scene's
// frame-0 rays (all hits), and so does an AVX2 loop over the boxes in structure-of-arrays form, eight
// slab tests per instruction, hits collected per ray. Both run in one process on the same data,
// alternating, `repeats` times; the ratio of their medians says how honest brute force is as the
// baseline of every "× bf" figure (a slow bf would flatter every structure).
//
//   build/bench/bf_baseline SCENE [REPEATS]      SCENE: a .rcbscene file or a preset (irreg-l, …)
#include <immintrin.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_util.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "accel/scan/brute_force.h"

namespace {

using namespace rcb;

/// The boxes per axis, padded to a multiple of eight with empty boxes (min > max: never hit).
struct SoaScene {
    std::vector<float> lo[3], hi[3];
    std::vector<Uid> uids;
    explicit SoaScene(const std::vector<Object>& objects) {
        const std::size_t n = (objects.size() + 7) / 8 * 8;
        for (int a = 0; a < 3; ++a) lo[a].assign(n, 1.0f), hi[a].assign(n, -1.0f);
        uids.assign(n, 0);
        for (std::size_t i = 0; i < objects.size(); ++i) {
            for (int a = 0; a < 3; ++a) lo[a][i] = objects[i].box.min[a], hi[a][i] = objects[i].box.max[a];
            uids[i] = objects[i].uid;
        }
    }
};

#ifdef __AVX2__
/// All hits of every ray, eight boxes per slab test; returns the hit count.
std::size_t cast_avx2(const SoaScene& s, const std::vector<Segment>& rays, std::vector<Uid>& hits) {
    hits.clear();
    const std::size_t n = s.uids.size();
    for (const Segment& r : rays) {
        const SegmentSlabs slabs(r);
        __m256 org[3], inv[3];
        const float* near[3];
        const float* far[3];
        for (int a = 0; a < 3; ++a) {
            org[a] = _mm256_set1_ps(slabs.origin[a]);
            inv[a] = _mm256_set1_ps(slabs.inv[a]);
            near[a] = slabs.near_is_max[a] ? s.hi[a].data() : s.lo[a].data();
            far[a] = slabs.near_is_max[a] ? s.lo[a].data() : s.hi[a].data();
        }
        for (std::size_t i = 0; i < n; i += 8) {
            __m256 tn = _mm256_setzero_ps(), tf = _mm256_set1_ps(1.0f);
            for (int a = 0; a < 3; ++a) {
                const __m256 l = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(near[a] + i), org[a]), inv[a]);
                const __m256 h = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(far[a] + i), org[a]), inv[a]);
                tn = _mm256_max_ps(l, tn);  // NaN in l keeps tn, as geometry.h's max_ignoring_nan
                tf = _mm256_min_ps(h, tf);
            }
            for (unsigned m = unsigned(_mm256_movemask_ps(_mm256_cmp_ps(tn, tf, _CMP_LE_OQ))); m; m &= m - 1)
                hits.push_back(s.uids[i + unsigned(__builtin_ctz(m))]);
        }
    }
    return hits.size();
}
#endif

int run(int argc, char** argv) {
    if (argc < 2 || argc > 3) throw InputError("usage: bf_baseline SCENE [REPEATS] (SCENE: .rcbscene file or preset)");
    const std::string what = argv[1];
    const int repeats = argc == 3 ? int(bench::count_arg(argv[2], "REPEATS", 1, 1000)) : 5;
    const Recording rec = std::filesystem::exists(what) ? read_recording(what) : generate_scene(preset_settings(what));
    if (rec.frames.empty() || rec.frames[0].rays.empty()) throw InputError(what + ": no rays in frame 1");
    const std::vector<Segment>& rays = rec.frames[0].rays;
    BruteForce bf;
    bf.build(rec.initial);
    HitLists out;
#ifdef __AVX2__
    const SoaScene soa(rec.initial);
    std::vector<Uid> hits;
    std::vector<double> t_bf, t_avx;
    std::size_t n_bf = 0, n_avx = 0;
    using clock = std::chrono::steady_clock;
    for (int r = 0; r < repeats; ++r) {
        auto t0 = clock::now();
        bf.cast(rays, out);
        auto t1 = clock::now();
        n_avx = cast_avx2(soa, rays, hits);
        auto t2 = clock::now();
        n_bf = out.uids.size();
        t_bf.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
        t_avx.push_back(std::chrono::duration<double, std::milli>(t2 - t1).count());
    }
    const double tests = double(rays.size()) * double(rec.initial.size());
    auto line = [&](const char* name, const std::vector<double>& t) {
        std::printf("%-10s median %8.3f ms  (min %.3f, max %.3f)  %.3f ns per box test\n", name, median(t),
                    *std::min_element(t.begin(), t.end()), *std::max_element(t.begin(), t.end()),
                    median(t) * 1e6 / tests);
    };
    std::printf("%s: %zu objects, %zu rays, %d repeats; hits bf %zu, avx2 %zu\n", what.c_str(), rec.initial.size(),
                rays.size(), repeats, n_bf, n_avx);
    line("bf", t_bf);
    line("avx2 loop", t_avx);
    std::printf("ratio bf / avx2 loop: %.3f\n", median(t_bf) / median(t_avx));
    return 0;
#else
    throw InputError("this build has no AVX2 (configure with RCB_NATIVE on an AVX2 machine)");
#endif
}

}  // namespace

int main(int argc, char** argv) { return rcb::bench::main_of("bf_baseline", run, argc, argv); }
