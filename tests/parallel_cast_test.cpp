// Parallel ray batches (`cast_threads`): every own structure and the peers that allow it give, with
// two threads and for every query kind, the hit lists of one thread byte for byte (same hits, same
// order, same ray boundaries) and the same counters, and are exact against the ground truth; the
// threads share a batch by taking chunks of rays one at a time, so a heavy ray does not hold up the
// rest of the batch.
#include <gtest/gtest.h>

#include <tbb/global_control.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "accel/model/counter_fields.h"
#include "accel/peers/bullet_dbvt.h"
#include "accel/peers/embree_boxes.h"
#include "accel/registry.h"
#include "accel/scan/brute_force.h"
#include "core/base/error.h"
#include "core/base/random.h"
#include "accel/bvh/dynamic_bvh.h"
#include "accel/grid/hash_grid.h"
#include "accel/bvh/linear_bvh.h"
#include "accel/grid/uniform_grid.h"
#include "accel/bvh/wide_bvh.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

const char* const kOwn[] = {"bf", "ug", "hg", "dbvh", "lbvh", "wbvh"};

TEST(ParallelCast, EveryOwnStructureMatchesGroundTruthWithTwoThreads) {
    // The simulator also compares the timed (parallel) pass with the counting (one-thread) pass
    // byte for byte and throws on any difference.
    for (const char* name : kOwn)
        for (const test::NamedScene& s : test::hard_scenes()) {
            test::expect_matches_ground_truth(s.recording, name, {{"cast_threads", 2}}, s.name);
            test::expect_matches_ground_truth(s.recording, name, {{"cast_threads", 2}, {"query", "candidates"}},
                                              s.name);
        }
}

/// Each ray of `rays` asking `kind`, or (nullopt) the kinds in turn: closest, any, all.
std::vector<QueryKind> kinds_of(const std::vector<Segment>& rays, std::optional<QueryKind> kind) {
    std::vector<QueryKind> kinds(rays.size(), kind.value_or(QueryKind::all));
    if (!kind)
        for (std::size_t i = 0; i < kinds.size(); ++i) kinds[i] = QueryKind((i + 1) % kQueryKinds);
    return kinds;
}

/// Replays `r` into S with one and with two cast threads and compares every frame's batch as all
/// hits, as closest hits, as any hits and with the kinds mixed, and the closest and the any hit of
/// every ray; `candidates` at the candidate level.
template <class S>
void expect_same_as_one_thread(const test::NamedScene& scene, bool candidates, const char* name) {
    typename S::Params one, two;
    two.cast_threads = 2;
    S a(one), b(two);
    ASSERT_EQ(b.cast_threads(), 2);
    a.set_candidates_only(candidates);
    b.set_candidates_only(candidates);
    a.build(scene.recording.initial);
    b.build(scene.recording.initial);
    HitLists ha, hb;
    std::size_t parallel_batches = 0;
    for (std::size_t f = 0; f < scene.recording.frames.size(); ++f) {
        const Frame& frame = scene.recording.frames[f];
        for (S* s : {&a, &b}) {
            for (Uid uid : frame.removes) s->remove(uid);
            for (const Object& o : frame.inserts) s->insert(o);
            for (const Object& o : frame.moves) s->move(o);
            s->commit();
        }
        const std::string where = std::string(name) + " " + scene.name + " frame " + std::to_string(f);
        for (const std::optional<QueryKind> kind : {std::optional<QueryKind>(), std::optional(QueryKind::all),
                                                    std::optional(QueryKind::closest), std::optional(QueryKind::any)}) {
            const std::vector<QueryKind> kinds = kinds_of(frame.rays, kind);
            a.cast(frame.rays, kinds, ha);
            b.cast(frame.rays, kinds, hb);
            EXPECT_EQ(a.last_cast_chunks(), 1u);
            parallel_batches += b.last_cast_chunks() > 1;
            const std::string batch = where + (kind ? std::string(" ") + query_kind_name(*kind) : " mixed");
            ASSERT_EQ(ha.offsets, hb.offsets) << batch;
            ASSERT_EQ(ha.uids, hb.uids) << batch;
        }
        for (const Segment& ray : frame.rays) {
            const auto ca = a.cast_closest(ray), cb = b.cast_closest(ray);
            ASSERT_EQ(ca.has_value(), cb.has_value()) << where;
            if (ca) {
                EXPECT_TRUE(ca->uid == cb->uid && ca->t == cb->t) << where;
            }
            EXPECT_EQ(a.cast_any(ray), b.cast_any(ray)) << where;
        }
        b.check();
    }
    // Batches of kParallelRays or more run in chunks; the hard scenes cast 64 rays per frame.
    std::size_t big = 0;
    for (const Frame& frame : scene.recording.frames) big += frame.rays.size() >= S::kParallelRays ? 4 : 0;
    EXPECT_EQ(parallel_batches, big) << name << " " << scene.name;
}

template <class S>
void check_structure(const char* name) {
    std::vector<test::NamedScene> scenes = test::hard_scenes();
    scenes.push_back({"irregular-3000", test::generated_scene("irregular", 3000, 4, 7, 0.2)});
    for (const test::NamedScene& s : scenes)
        for (bool candidates : {false, true}) expect_same_as_one_thread<S>(s, candidates, name);
}

TEST(ParallelCast, HitListsIdenticalToOneThread) {
    check_structure<BruteForce>("bf");
    check_structure<UniformGrid>("ug");
    check_structure<HashGrid>("hg");
    check_structure<DynamicBvh>("dbvh");
    check_structure<LinearBvh>("lbvh");
    check_structure<WideBvh>("wbvh");
    check_structure<EmbreeBoxes>("embree");
    check_structure<BulletDbvt>("bullet_dbvt");
}

/// `r` with every ray asking `kind`, or (nullopt) the kinds in turn (the simulator then casts one
/// batch per kind).
Recording asking(Recording r, std::optional<QueryKind> kind) {
    for (Frame& f : r.frames) {
        f.kinds = kinds_of(f.rays, kind);
        if (kind == QueryKind::all) f.kinds.clear();
    }
    return r;
}

TEST(ParallelCast, EveryStructureAndPeerGivesTheOneThreadResultsForEveryQueryKind) {
    // Through the simulator, verified against the ground truth: with two cast threads every frame's
    // hits, mismatches and counters (the counting pass, on the calling thread) are those of one, per
    // query kind too. A structure without `cast_threads` is a peer whose library forbids
    // concurrent queries (ODE: docs/structures.md) and refuses two threads.
    const Recording scene = test::generated_scene("irregular", 800, 3, 11, 0.1);
    std::size_t parallel = 0;
    for (const StructureInfo& info : structure_registry()) {
        const bool threaded = std::any_of(info.params.begin(), info.params.end(),
                                          [](const ParamSpec& p) { return p.name == "cast_threads"; });
        if (!threaded) {
            EXPECT_TRUE(info.name.starts_with("ode_")) << info.name << " casts on one thread only";
            EXPECT_THROW(info.make({{"cast_threads", 2}}, "params"), InputError) << info.name;
            continue;
        }
        ++parallel;
        for (const std::optional<QueryKind> kind : {std::optional<QueryKind>(), std::optional(QueryKind::all),
                                                    std::optional(QueryKind::closest), std::optional(QueryKind::any)}) {
            const Recording r = asking(scene, kind);
            const std::string what = info.name + (kind ? std::string(" ") + query_kind_name(*kind) : " mixed");
            const SimulationResult one =
                test::expect_matches_ground_truth(r, info.name, nlohmann::json::object(), what);
            const SimulationResult two = test::expect_matches_ground_truth(r, info.name, {{"cast_threads", 2}}, what);
            ASSERT_EQ(one.frames.size(), two.frames.size()) << what;
            for (std::size_t f = 0; f < one.frames.size(); ++f) {
                const FrameResult &x = one.frames[f], &y = two.frames[f];
                EXPECT_EQ(x.hits, y.hits) << what << " frame " << f;
                EXPECT_EQ(x.returned, y.returned) << what << " frame " << f;
                for (const CounterField& c : kCounterFields)
                    EXPECT_EQ(x.counters.*c.member, y.counters.*c.member) << what << " frame " << f << " " << c.name;
                ASSERT_EQ(x.kinds.size(), y.kinds.size()) << what;
                for (std::size_t k = 0; k < x.kinds.size(); ++k) {
                    EXPECT_EQ(x.kinds[k].hits, y.kinds[k].hits) << what << " frame " << f;
                    for (const CounterField& c : kCounterFields)
                        EXPECT_EQ(x.kinds[k].counters.*c.member, y.kinds[k].counters.*c.member)
                            << what << " frame " << f << " " << c.name;
                }
            }
        }
    }
    EXPECT_EQ(parallel, 8u);  // the six own structures, Embree and Bullet
}

TEST(ParallelCast, ChunksCoverTheBatchShrinkAndJoinInRayOrderWhoeverCastThem) {
    for (const std::size_t rays : {32u, 33u, 100u, 1000u, 4096u}) {
        RayChunks chunks;
        chunks.plan(rays, 2);
        ASSERT_GT(chunks.chunks(), 1u);
        EXPECT_EQ(chunks.begin(0), 0u);
        EXPECT_EQ(chunks.begin(chunks.chunks() - 1) + chunks.size(chunks.chunks() - 1), rays);
        for (std::size_t c = 0; c + 1 < chunks.chunks(); ++c) {
            EXPECT_EQ(chunks.begin(c) + chunks.size(c), chunks.begin(c + 1));
            EXPECT_GE(chunks.size(c), RayChunks::kMinRays);
            EXPECT_GE(chunks.size(c), chunks.size(c + 1));  // long first, short last
            EXPECT_EQ(chunks.chunk_of(chunks.begin(c + 1) - 1), c);
        }
        // No chunk holds more than a sixteenth of the batch with two threads (kShare = 8).
        EXPECT_LE(chunks.size(0), (rays + 15) / 16 + RayChunks::kMinRays);
        // Chunks cast in a shuffled order by slots drawn at random: ray i's list is {i, i + 1} for
        // odd i, empty for even i; joined, the lists are in ray order.
        std::vector<std::size_t> order(chunks.chunks());
        for (std::size_t c = 0; c < order.size(); ++c) order[c] = c;
        Random rng(rays);
        for (std::size_t i = order.size(); i > 1; --i) std::swap(order[i - 1], order[rng.below(i)]);
        for (const std::size_t c : order) {
            HitLists& lists = chunks.start(c, int(rng.below(2)));
            for (std::size_t r = chunks.begin(c); r < chunks.begin(c) + chunks.size(c); ++r) {
                if (r % 2) lists.uids.insert(lists.uids.end(), {Uid(r), Uid(r + 1)});
                lists.end_ray();
            }
        }
        HitLists joined, expected;
        chunks.join(joined);
        for (std::size_t r = 0; r < rays; ++r) {
            if (r % 2) expected.uids.insert(expected.uids.end(), {Uid(r), Uid(r + 1)});
            expected.end_ray();
        }
        EXPECT_EQ(joined.offsets, expected.offsets) << rays;
        EXPECT_EQ(joined.uids, expected.uids) << rays;
        const std::vector<std::size_t> per_slot = chunks.rays_per_slot();
        EXPECT_EQ(per_slot[0] + per_slot[1], rays);
    }
}

/// A structure whose ray i (its start's x) hits object i, and whose ray 0 is heavy: it returns only
/// once every ray outside its own chunk has been cast (or after a minute). With a split bound to
/// threads beforehand (halves, or a few chunks per thread) the rays after ray 0 in its part wait
/// behind it and the minute runs out; with chunks taken one at a time the other thread casts them.
struct HeavyScratch {
    std::size_t memory_bytes() const { return 0; }
};
class HeavyFirstRay : public StructureBase<HeavyFirstRay, HeavyScratch> {
public:
    HeavyFirstRay(int threads, std::size_t wait_for) : wait_for_(wait_for) { set_cast_threads(threads); }
    void build(std::span<const Object>) override {}
    void insert(const Object&) override {}
    void remove(Uid) override {}
    void move(const Object&) override {}
    std::size_t size() const override { return 0; }
    std::size_t memory_bytes() const override { return 0; }
    void check() const override {}

    void prepare() {}
    void fit(HeavyScratch&) const {}
    template <class Count, class Visit>
    void traverse(const Segment& s, Count&, Visit&& visit, HeavyScratch&) const {
        const auto ray = Uid(s.p0.x);
        if (ray == 0) {
            const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(1);
            while (light_done_.load() < wait_for_ && std::chrono::steady_clock::now() < deadline)
                std::this_thread::sleep_for(std::chrono::microseconds(100));
            waited_out_ = light_done_.load() < wait_for_;
        } else {
            ++light_done_;
        }
        visit(ray, 0.0f);
    }
    bool waited_out() const { return waited_out_; }

private:
    std::size_t wait_for_;
    mutable std::atomic<std::size_t> light_done_{0};
    mutable std::atomic<bool> waited_out_{false};
};

TEST(ParallelCast, AHeavyRayDoesNotHoldUpTheRestOfTheBatch) {
    // Two threads for TBB whatever the affinity mask (tests may run pinned to one core): the test
    // checks who cast what, not how fast.
    const tbb::global_control two(tbb::global_control::max_allowed_parallelism, 2);
    const std::size_t n = 512;
    RayChunks plan;
    plan.plan(n, 2);
    const std::size_t heavy_chunk = plan.size(0);
    ASSERT_LE(heavy_chunk, n / 16);
    std::vector<Segment> rays;
    for (std::size_t i = 0; i < n; ++i) rays.push_back({{float(i), 0, 0}, {float(i), 1, 0}});
    for (const std::optional<QueryKind> kind : {std::optional<QueryKind>(), std::optional(QueryKind::all),
                                                std::optional(QueryKind::closest), std::optional(QueryKind::any)}) {
        HeavyFirstRay s(2, n - heavy_chunk);
        HitLists out;
        s.cast(rays, kind ? kinds_of(rays, kind) : std::vector<QueryKind>{}, out);
        ASSERT_FALSE(s.waited_out()) << "the rays after the heavy one waited behind it";
        // The thread of the heavy ray cast its chunk and nothing else; the other one all the rest.
        std::vector<std::size_t> per_slot = s.last_cast_rays_per_slot();
        std::sort(per_slot.begin(), per_slot.end());
        EXPECT_EQ(per_slot, (std::vector<std::size_t>{heavy_chunk, n - heavy_chunk}));
        ASSERT_EQ(out.rays(), n);
        for (std::size_t i = 0; i < n; ++i)
            EXPECT_EQ(std::vector<Uid>(out.of(i).begin(), out.of(i).end()), (std::vector<Uid>{Uid(i)}));
    }
}

TEST(ParallelCast, ThesisResetModeOfTheUniformGrid) {
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(s.recording, "ug", {{"thesis_reset", true}, {"cast_threads", 2}}, s.name);
}

}  // namespace
}  // namespace rcb
