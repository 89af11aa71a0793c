// Structure::update_work(): the update's work that its writes do not show. That the linear BVH
// counts the keys its radix sort placed (none beyond the merged ones when it merges from the last
// order), that the wide BVH counts the blocks of each reinsertion's descent and its rebuilds' work,
// that the simulator stores the count per frame, and that a run stored before it existed offers no
// form that prices it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "accel/bvh/linear_bvh.h"
#include "accel/bvh/wide_bvh.h"
#include "accel/registry.h"
#include "analysis/cost_model.h"
#include "core/base/random.h"
#include "runner/experiment.h"
#include "runner/merge.h"
#include "runner/store.h"
#include "sim/simulator.h"
#include "tests/test_db.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

using test::count;

/// The growth of s.update_work() and s.writes() over one frame: `moves`, then the commit.
struct Growth {
    std::uint64_t work = 0, writes = 0;
};
Growth frame_of(Structure& s, const std::vector<Object>& moves) {
    const std::uint64_t work = s.update_work(), writes = s.writes();
    for (const Object& o : moves) s.move(o);
    s.commit();
    return {s.update_work() - work, s.writes() - writes};
}

/// `k` objects of `objects` moved, each onto the box of another object at the far side of the
/// list (their centres stay inside the centroid bounds, their Morton codes change).
std::vector<Object> swapped_moves(const std::vector<Object>& objects, std::size_t k) {
    std::vector<Object> moves;
    const std::size_t n = objects.size(), stride = n / (k + 1);
    for (std::size_t i = 1; i <= k; ++i) {
        const Object& o = objects[i * stride];
        moves.emplace_back(o.uid, objects[n - 1 - i * stride].box);
    }
    return moves;
}

TEST(UpdateWork, LinearBvhCountsTheKeysItsRadixSortPlacedAndOnlyTheOutOfOrderOnesWhenItMerges) {
    // 20000 objects: above the merge's threshold (4 × 2048 top digits).
    const std::vector<Object> objects = test::generated_scene("uniform", 20000, 1, 7).initial;
    const std::size_t n = objects.size();
    LinearBvh merging, sorting(LinearBvh::Params{.coherent_sort = false});
    for (LinearBvh* t : {&merging, &sorting}) {
        t->build(objects);
        EXPECT_EQ(t->update_work(), n);  // the build sorts every key
    }
    // k changed objects of n (k ≤ n/16): the merge sorts apart the keys out of the last order, each
    // changed key or at most 8 kept keys beside it, and places every other key by the merge.
    const std::size_t k = 40;
    const std::vector<Object> few = swapped_moves(objects, k);
    const Growth merged = frame_of(merging, few);
    ASSERT_TRUE(merging.last_resorted());
    EXPECT_GE(merged.work, k / 2);
    EXPECT_LE(merged.work, 8 * k);
    // The same frame sorted: n keys, with fewer writes than the merge's (which stages every leaf
    // record): the writes cannot tell the two apart, the work can.
    const Growth sorted = frame_of(sorting, few);
    ASSERT_FALSE(sorting.last_resorted());
    EXPECT_EQ(sorted.work, n);
    EXPECT_LT(sorted.writes, merged.writes);
    EXPECT_EQ(merging.nodes(), sorting.nodes());  // the same tree either way
    // More than n/16 changed: the radix path, n keys.
    const Growth many = frame_of(merging, swapped_moves(objects, n / 8));
    EXPECT_FALSE(merging.last_resorted());
    EXPECT_EQ(many.work, n);
    // No change: no rebuild, no work.
    EXPECT_EQ(frame_of(merging, {}).work, 0u);
    merging.check();
}

/// 32 objects in 4 clusters of 8 far apart on x: with leaves of 8, a root over 4 leaves.
std::vector<Object> clusters() {
    std::vector<Object> objects;
    Uid uid = 1;
    for (int c = 0; c < 4; ++c)
        for (int i = 0; i < 8; ++i) {
            const Vec3 at{100.0f * float(c) + float(i % 2), float(i / 2 % 2), float(i / 4)};
            objects.emplace_back(uid++, Aabb{at, at + Vec3{0.5f, 0.5f, 0.5f}});
        }
    return objects;
}

TEST(UpdateWork, WideBvhCountsTheBlocksEachReinsertionsDescentRead) {
    const std::vector<Object> objects = clusters();
    WideBvh::Params p;
    p.rebuild_ratio = 0, p.rebuild_after = 0;  // no rebuild: the moves alone
    WideBvh t(p);
    t.build(objects);
    t.commit();
    ASSERT_EQ(t.depth(), 1);  // the root and its leaves: a descent reads 2 blocks
    const std::uint64_t reinserts = t.update_counts().reinserts;
    // A small step inside its leaf: a lane rewritten, no descent.
    const Object& first = objects[0];
    EXPECT_EQ(frame_of(t, {Object(first.uid, Aabb{first.box.min + Vec3{0.01f, 0, 0}, first.box.max})}).work, 0u);
    EXPECT_EQ(t.update_counts().reinserts, reinserts);
    // r objects of the first cluster moved into the last one: r reinsertions, each a descent from
    // the root to a leaf (the full leaf splits under the root, which has room: depth stays 1).
    const std::size_t r = 3;
    std::vector<Object> far;
    for (std::size_t i = 1; i <= r; ++i)
        far.emplace_back(objects[i].uid,
                         Aabb{objects[i].box.min + Vec3{300.0f, 0, 0}, objects[i].box.max + Vec3{300.0f, 0, 0}});
    const Growth g = frame_of(t, far);
    EXPECT_EQ(t.update_counts().reinserts - reinserts, r);
    EXPECT_EQ(t.depth(), 1);
    EXPECT_EQ(g.work, 2 * r);
    // An insert descends too.
    const std::uint64_t before = t.update_work();
    t.insert(Object(1000, objects[20].box));
    t.commit();
    EXPECT_EQ(t.update_work() - before, 2u);
    t.check();
    // Without reinsertion the same moves stay in their leaves (which grow): no descent.
    WideBvh::Params q = p;
    q.reinsert = false;
    WideBvh keeping(q);
    keeping.build(objects);
    keeping.commit();
    EXPECT_EQ(frame_of(keeping, far).work, 0u);
    keeping.check();
}

/// The growth of t's rebuild units over one frame in update_work()'s unit (16 per descent block),
/// with its whole-unit remainder carried as update_work() carries it.
std::uint64_t rebuild_blocks(std::uint64_t units_before, std::uint64_t units_after) {
    return units_after / 16 - units_before / 16;
}

TEST(UpdateWork, WideBvhCountsItsRebuildsWorkBesideTheDescents) {
    // A frame that starts or advances a rebuild takes the rebuild's time, which neither its
    // descents nor its writes showed: update_work() adds the rebuild's units, 16 per block.
    const std::vector<Object> objects = test::generated_scene("uniform", 2000, 1, 7).initial;
    // A step far inside the object's leaf: no reinsertion, no descent; only the rebuild works.
    const Object& first = objects[0];
    auto nudge = [&](int i) {
        const Vec3 d{0.001f * float(i), 0, 0};
        return std::vector<Object>{Object(first.uid, Aabb{first.box.min + d, first.box.max + d})};
    };
    WideBvh::Params p;
    p.rebuild_ratio = 0.5, p.rebuild_after = 0;  // a ratio in (0, 1]: a rebuild at every commit after a change
    for (const double speed : {0.0, 4.0}) {      // the whole rebuild in the commit; a progressive one
        SCOPED_TRACE(speed);
        p.rebuild_speed = speed;
        WideBvh t(p);
        t.build(objects);
        t.commit();
        EXPECT_EQ(t.update_work(), 0u);  // the build is not an update
        std::uint64_t total_units = 0;
        for (int i = 1; i <= 40; ++i) {
            const WideBvh::UpdateCounts before = t.update_counts();
            const Growth g = frame_of(t, nudge(i));
            const WideBvh::UpdateCounts& after = t.update_counts();
            ASSERT_EQ(after.reinserts, before.reinserts);
            total_units += after.rebuild_work - before.rebuild_work;
            // A progressive rebuild's replay descends into its next tree, counted as before.
            const std::uint64_t rebuilt = rebuild_blocks(before.rebuild_work, after.rebuild_work);
            if (speed == 0.0)
                EXPECT_EQ(g.work, rebuilt) << i;
            else
                EXPECT_GE(g.work, rebuilt) << i;
        }
        t.check();
        // The whole rebuild builds every object at every commit (several units each); the
        // progressive one spends 4 objects' share of a build per change, still gathering.
        if (speed == 0.0) {
            EXPECT_EQ(t.update_counts().rebuilds, 40u);
            EXPECT_GT(total_units, 40u * 16u * objects.size());
        } else {
            EXPECT_GT(total_units, 16u * 40u);
        }
        EXPECT_GE(t.update_work(), total_units / 16);
    }
}

TEST(UpdateWork, EveryOtherStructureCountsNone) {
    const Recording r = test::generated_scene("irregular", 400, 4, 21, 0.1);
    for (const char* name : {"bf", "ug", "hg", "dbvh", "bullet_dbvt"}) {
        SCOPED_TRACE(name);
        auto s = find_structure(name).make(nlohmann::json::object(), "params");
        s->build(r.initial);
        for (const Frame& f : r.frames) {
            for (Uid uid : f.removes) s->remove(uid);
            for (const Object& o : f.inserts) s->insert(o);
            for (const Object& o : f.moves) s->move(o);
            s->commit();
        }
        EXPECT_EQ(s->update_work(), 0u);
    }
}

TEST(UpdateWork, ReachesTheDatabasePerFrameSurvivesAMergeAndIsNullInOlderFrames) {
    const test::TempDir temp("update_work", "store");
    const std::string a = temp.file("a.db"), b = temp.file("b.db");
    { ResultStore old(a, latest_schema_version() - 1); }  // the schema before the column
    const Experiment e =
        parse_experiment(R"({"scenes": [{"preset": "uni-s"}], "structures": [{"name": "lbvh"}]})", "work", ".");
    const Recording rec = test::generated_scene("uniform", 300, 5, 4, 0.05);
    const SimulationResult res = simulate(rec, find_structure("lbvh"), nlohmann::json::object());
    std::uint64_t total = 0;
    for (const FrameResult& f : res.frames) {
        EXPECT_EQ(f.update_work, f.inserts + f.removes + f.moves > 0 ? 300u : 0u) << f.frame;  // radix: n keys
        total += f.update_work;
    }
    ASSERT_GT(total, 0u);
    {
        ResultStore store(a);  // migrated on open: frames stored before would be NULL
        const std::int64_t ex = store.experiment_id(e);
        const std::int64_t run = store.begin_run(ex, RunInfo::current(1, "", e));
        ASSERT_TRUE(store.store_cell(run, ex, e.plan[0], e.scenes[0], rec, recording_hash(rec), res));
        EXPECT_EQ(count(store.db(), "SELECT sum(update_work) FROM frame"), std::int64_t(total));
        EXPECT_EQ(count(store.db(), "SELECT count(*) FROM frame WHERE update_work IS NULL"), 0);
    }
    {
        ResultStore merged(b);
        EXPECT_EQ(merge_into(merged, *open_read_only(a)).cells, 1u);
        EXPECT_EQ(count(merged.db(), "SELECT sum(update_work) FROM frame"), std::int64_t(total));
        // A frame stored before the column existed: NULL, not 0, and it stays so through a merge.
        merged.db().exec(
            "UPDATE frame SET update_work = NULL WHERE frame = (SELECT min(frame) FROM frame WHERE warmup = 0)");
    }
    const std::string c = temp.file("c.db");
    {
        ResultStore again(c);
        merge_into(again, *open_read_only(b));
        EXPECT_EQ(count(again.db(), "SELECT count(*) FROM frame WHERE update_work IS NULL AND warmup = 0"), 1);
    }
    // Read back for the model: the NULL frame's work is not recorded (NaN), the others as stored.
    const std::vector<FrameObservation> frames = load_observations(*open_read_only(c), 1, OverRepetitions::median);
    ASSERT_FALSE(frames.empty());
    std::size_t unrecorded = 0;
    for (const FrameObservation& f : frames) {
        if (std::isnan(f.update_work))
            ++unrecorded;
        else
            EXPECT_EQ(f.update_work, f.inserts + f.removes + f.moves > 0 ? 300.0 : 0.0);
    }
    EXPECT_EQ(unrecorded, 1u);
}

/// One rebuilding tree's frames on scenes of 300 to 40000 objects, 1% of them changed: 45 ns per
/// object and 30 per key its radix sort placed (every key below 8192 objects, the changed ones
/// above, where it merges), or with `work` false the same times without the counter (a run stored
/// before it: NaN).
std::vector<FrameObservation> rebuild_frames(bool work) {
    Random rng(5);
    std::vector<FrameObservation> frames;
    for (int s = 0; s < 14; ++s) {
        const double objects = std::round(rng.log_uniform(300, 40000)), changes = std::round(0.01 * objects);
        const double sorted = objects < 8192 ? objects : 2 * changes;
        for (int f = 0; f < 10; ++f) {
            FrameObservation o;
            o.structure = "lbvh";
            o.scene = "scene" + std::to_string(s);
            o.params = "{}";
            o.config_group = s;
            o.objects = objects;
            o.moves = changes;
            o.writes = (sorted == objects ? 3 : 4) * objects;
            o.update_work = work ? sorted : NAN;
            o.update_ns = (45 * objects + 30 * sorted + 2000) * (1 + 0.02 * rng.normal());
            frames.push_back(o);
        }
    }
    return frames;
}

TEST(UpdateWork, TheWorkFormPricesARebuildingTreeThatSortsOrMerges) {
    const auto models = fit_cost_models(rebuild_frames(true));
    ASSERT_EQ(models.size(), 1u);
    const CandidateModel* m = models[0].chosen("update");
    ASSERT_NE(m, nullptr);
    EXPECT_EQ(m->name, "per-change-work");
    EXPECT_LT(m->heldout_error, 0.05);
    const auto work = std::find_if(m->fit.coefficients.begin(), m->fit.coefficients.end(),
                                   [](const Coefficient& c) { return c.name == "c_work"; });
    ASSERT_NE(work, m->fit.coefficients.end());
    EXPECT_NEAR(work->value, 30.0, 6.0);
    // One price per change charges the merged scenes the sorted ones' price.
    for (const CandidateModel& c : models[0].update)
        if (c.name == "per-change") {
            EXPECT_GT(c.heldout_error, 3 * m->heldout_error);
        }
}

TEST(UpdateWork, ARunWithoutTheCounterOffersNoFormThatPricesIt) {
    const auto models = fit_cost_models(rebuild_frames(false));
    ASSERT_EQ(models.size(), 1u);
    ASSERT_FALSE(models[0].update.empty());
    for (const CandidateModel& c : models[0].update) {
        EXPECT_NE(c.name, "per-change-work");
        for (const std::string& t : c.problem.terms) EXPECT_EQ(t.find("c_work"), std::string::npos) << c.name;
    }
    EXPECT_EQ(models[0].chosen("update")->name, "per-change");
}

}  // namespace
}  // namespace rcb
