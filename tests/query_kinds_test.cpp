// Query kinds (all | closest | any): the ground truth per kind, every registered structure and
// peer against it, the verification's verdicts, the recording with kinds and --query-mix.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "accel/registry.h"
#include "core/base/error.h"
#include "core/scene/generate/generators.h"
#include "core/scene/recording_io.h"
#include "sim/simulator.h"
#include "core/truth/ground_truth.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

Object box(Uid uid, Vec3 min, Vec3 max) { return {uid, Aabb{min, max}}; }

/// Whether the segment meets object `uid`'s box, in double.
bool meets(const Segment& ray, const std::vector<Object>& objects, Uid uid) {
    for (const Object& o : objects)
        if (o.uid == uid)
            return classify_contact({ray.p0.as<double>(), ray.p1.as<double>()}, o.box.as<double>()) != Contact::miss;
    return false;
}

/// Hand-made cases with exactly representable entries: ties (uids 7 and 3 entered at t = 0.25),
/// a start inside boxes (t = 0), a segment grazing a face, and misses.
struct Case {
    Segment ray;
    std::optional<Uid> closest;
    double t = 0;
};

std::vector<Object> tie_objects() {
    return {
        box(7, {2, -1, -1}, {3, 1, 1}),           // entered at x = 2: t = 0.25 on the x ray
        box(3, {2, 0, -1}, {4, 2, 1}),            // also entered at x = 2 (a tie), uid smaller
        box(9, {5, -1, -1}, {6, 1, 1}),           // behind both
        box(4, {-1, 10, -1}, {1, 12, 1}),         // the segment up the y axis starts inside it
        box(2, {-2, 11, -2}, {2, 13, 2}),         // entered later on that segment, smaller uid
        box(5, {10, 20, 0}, {12, 22, 2}),         // its face z = 2 is grazed
        box(6, {10, 20, 3}, {12, 22, 5}),         // entered later along the grazing segment
        box(1, {100, 100, 100}, {101, 101, 101})  // never met
    };
}

std::vector<Case> tie_cases() {
    return {
        {{{0, 0, 0}, {8, 0, 0}}, Uid(3), 0.25},         // tie at t = 0.25 → smaller uid
        {{{8, 0, 0}, {0, 0, 0}}, Uid(9), 0.25},         // reversed: box 9 first at x = 6
        {{{0, 11, 0}, {0, 19, 0}}, Uid(2), 0.0},        // starts inside 4 and on 2's face: both t = 0
        {{{0, 10.5f, 0}, {0, 18.5f, 0}}, Uid(4), 0.0},  // inside 4 only; 2 entered at t = 0.0625
        {{{8, 21, 2}, {16, 21, 2}}, Uid(5), 0.25},      // in the plane z = 2: grazes 5's face
        {{{11, 21, 8}, {11, 21, 0}}, Uid(6), 0.375},    // down through 6 onto 5's face
        {{{0, 50, 0}, {8, 50, 0}}, std::nullopt, 0},    // misses everything
        {{{2.5f, 0, 0}, {2.5f, 0, 0}}, Uid(3), 0.0},    // a point inside 7 and 3
    };
}

/// A tie across a cell plane of the grids: the world is [0, 8]³, and the hash grid configured by
/// plane_tie_grid() has cells of edge 4, 2, 1 and 0.5 at depths 0..3, so x = 4 is a plane at
/// every depth. The ray (t = x / 8) meets box `a` at t = 0.5 through its y face: `a` reaches back
/// into the cells before x = 4 that the ray crosses, so a grid finds it there and its closest-hit
/// limit becomes 0.5 before it enters the cells beyond the plane, exactly at 0.5, where alone box
/// `b` (entered through its x face at the same point) is stored. Whichever has the smaller uid
/// must win, so the walk must not cut off a cell entered exactly at its limit.
std::vector<Object> plane_tie_objects(Uid a, Uid b) {
    std::vector<Object> objects{
        box(a, {3.625f, 4.25f, 4}, {5, 4.5f, 4.5f}),  // entered at (4, 4.25, 4.25) through y = 4.25
        box(b, {4, 3, 4}, {5, 5, 4.5f}),              // entered there too, through x = 4
        box(20, {6, 4, 4}, {7, 5, 5}),                // behind both
        box(21, {0, 0, 0}, {0.25f, 0.25f, 0.25f}),    // corners: the world is [0, 8]³
        box(22, {7.75f, 7.75f, 7.75f}, {8, 8, 8})};
    // Off the ray, beside the tie: crowded cells split at small capacities.
    for (Uid u = 0; u < 11; ++u) {
        const float x = 3.5f + 0.25f * float(u % 4), z = 5.25f + 0.5f * float(u / 4);
        objects.push_back(box(30 + u, {x, 4, z}, {x + 0.25f, 4.5f, z + 0.25f}));
    }
    return objects;  // 16 objects
}

std::vector<Case> plane_tie_cases(Uid winner) {
    return {
        {{{0, 3.75f, 4.25f}, {8, 4.75f, 4.25f}}, winner, 0.5},     // the tie across x = 4
        {{{8, 4.25f, 4.25f}, {0, 4.25f, 4.25f}}, Uid(20), 0.125},  // backwards: 20 first at x = 7
    };
}

/// The hash grid parameters under which plane_tie_objects() has cell planes at x = 4 at every depth:
/// (16 objects × amp)^(1/3) = 2 top cells per axis.
nlohmann::json plane_tie_grid() { return {{"amp", 0.5}, {"max_depth", 3}, {"max_capacity", 1}, {"subdivision", 2}}; }

/// Hand-made scenes: objects and their cases.
struct TieScene {
    std::string name;
    std::vector<Object> objects;
    std::vector<Case> cases;
};

std::vector<TieScene> tie_scenes() {
    return {{"ties", tie_objects(), tie_cases()},
            {"plane tie, smaller uid behind the plane", plane_tie_objects(9, 3), plane_tie_cases(3)},
            {"plane tie, smaller uid before the plane", plane_tie_objects(3, 9), plane_tie_cases(3)}};
}

/// Every registered structure (own, thesis and peers) at its defaults, then more configurations
/// of the grids, whose closest-hit walks stop at the first cell entered after the best hit: the
/// hash grid at depths 0..3 with small capacities, so that cells subdivide and children walks
/// stop too, and the uniform grid with small cells.
std::vector<std::pair<std::string, nlohmann::json>> kind_configurations() {
    std::vector<std::pair<std::string, nlohmann::json>> out;
    for (const StructureInfo& info : structure_registry()) out.emplace_back(info.name, nlohmann::json::object());
    for (int depth = 0; depth <= 3; ++depth)
        out.emplace_back("hg", nlohmann::json{{"max_depth", depth},
                                              {"max_capacity", 1 + depth % 2},
                                              {"subdivision", 2 + depth / 2},
                                              {"amp", depth % 2 ? 0.5 : 4.0}});
    out.emplace_back("hg", plane_tie_grid());
    out.emplace_back("ug", nlohmann::json{{"density", 0.5}});
    return out;
}

TEST(QueryKinds, GroundTruthClosestBreaksTiesByUidAndStartsInsideAtZero) {
    for (const TieScene& scene : tie_scenes()) {
        const GroundTruth truth(scene.objects);
        for (const Case& c : scene.cases) {
            const auto got = truth.closest(c.ray);
            ASSERT_EQ(got.has_value(), c.closest.has_value()) << scene.name << ' ' << c.ray.p0.x << ',' << c.ray.p0.y;
            EXPECT_EQ(truth.any(c.ray), c.closest.has_value());
            if (!got) continue;
            EXPECT_EQ(got->uid, *c.closest) << scene.name << ' ' << c.ray.p0.x << ',' << c.ray.p0.y;
            EXPECT_EQ(got->t, c.t) << scene.name << ' ' << c.ray.p0.x << ',' << c.ray.p0.y;
        }
    }
}

/// Every configuration of kind_configurations(), with one batch per kind and with the single-ray
/// queries, against the truth of the hand-made cases.
TEST(QueryKinds, EveryStructureAnswersHandMadeTiesLikeTheTruth) {
    for (const TieScene& scene : tie_scenes()) {
        const GroundTruth truth(scene.objects);
        std::vector<Segment> rays;
        for (const Case& c : scene.cases) rays.push_back(c.ray);
        for (const auto& [name, params] : kind_configurations()) {
            std::unique_ptr<Structure> s = find_structure(name).make(params, "params");
            s->build(scene.objects);
            s->commit();
            HitLists closest, any;
            s->cast(rays, std::vector<QueryKind>(rays.size(), QueryKind::closest), closest);
            s->cast(rays, std::vector<QueryKind>(rays.size(), QueryKind::any), any);
            for (std::size_t i = 0; i < rays.size(); ++i) {
                const auto want = scene.cases[i].closest;
                const std::string where = scene.name + ": " + name + ' ' + params.dump() + " ray " + std::to_string(i);
                ASSERT_EQ(closest.of(i).size(), want ? 1u : 0u) << where;
                if (want) {
                    EXPECT_EQ(closest.of(i)[0], *want) << where;
                }
                const auto one = s->cast_closest(rays[i]);
                ASSERT_EQ(one.has_value(), want.has_value()) << where;
                if (one) {
                    EXPECT_EQ(one->uid, *want) << where;
                }
                ASSERT_EQ(any.of(i).size(), want ? 1u : 0u) << where;
                if (want) {
                    EXPECT_TRUE(truth.any(rays[i])) << where;
                }
                EXPECT_EQ(s->cast_any(rays[i]), want.has_value()) << where;
            }
        }
    }
}

/// A long batch of one kind per configuration of kind_configurations() on a random scene: closest
/// equals the truth's exact answer (random boxes and segments do not tie), any names a box the
/// segment meets.
TEST(QueryKinds, EveryStructureAgreesWithTheTruthOnRandomScenes) {
    Random rng(17);
    std::vector<Object> objects;
    for (Uid uid = 0; uid < 600; ++uid) objects.push_back({uid, test::random_box(rng, 60)});
    std::vector<Segment> rays;
    for (int i = 0; i < 400; ++i) rays.push_back(test::random_segment(rng, 60));
    const GroundTruth truth(objects);
    std::vector<QueryKind> kinds;
    for (std::size_t i = 0; i < rays.size(); ++i) kinds.push_back(QueryKind(i % kQueryKinds));
    for (const auto& [name, params] : kind_configurations()) {
        const std::string config = name + ' ' + params.dump();
        std::unique_ptr<Structure> s = find_structure(name).make(params, "params");
        s->build(objects);
        s->commit();
        HitLists hits;
        s->cast(rays, kinds, hits);
        EXPECT_EQ(truth.verify(rays, kinds, hits).mismatches(), 0u) << config;
        for (std::size_t i = 0; i < rays.size(); ++i) {
            const std::string where = config + " ray " + std::to_string(i);
            const auto want = truth.closest(rays[i]);
            if (kinds[i] == QueryKind::closest) {
                ASSERT_EQ(hits.of(i).size(), want ? 1u : 0u) << where;
                if (want) {
                    EXPECT_EQ(hits.of(i)[0], want->uid) << where;
                }
            } else if (kinds[i] == QueryKind::any) {
                ASSERT_EQ(hits.of(i).size(), want ? 1u : 0u) << where;
                if (want) {
                    EXPECT_TRUE(meets(rays[i], objects, hits.of(i)[0])) << where;
                }
            }
        }
        // The counting pass answers the same and counts no more work than all hits would.
        Counters mixed, all;
        HitLists counted, every;
        s->cast_counted(rays, kinds, counted, mixed);
        EXPECT_EQ(counted.uids, hits.uids) << config;
        s->cast_counted(rays, every, all);
        EXPECT_LE(mixed.n_rb, all.n_rb) << config;
    }
}

/// The BVHs prune for closest and any hits: along a row of boxes, the closest hit is the first box
/// met and every box behind it is entered after it, so a traversal near to far that culls by the
/// best hit reads a few nodes and objects where all hits reads them all; any hit stops at its
/// first. Both directions, so that the order cannot come from the build's lane order alone.
constexpr int kRowBoxes = 512;

/// kRowBoxes unit boxes in a row along x, one every two units.
std::vector<Object> row_of_boxes() {
    std::vector<Object> objects;
    for (int i = 0; i < kRowBoxes; ++i) {
        const float x = 2.0f * float(i);
        objects.push_back(box(Uid(i), {x, -1, -1}, {x + 1, 1, 1}));
    }
    return objects;
}

/// Two segments along the whole row, one each way (not parallel to an axis), and the first box
/// each meets.
std::vector<Segment> row_rays() {
    const float end = 2.0f * kRowBoxes + 1;
    return {{{-1, 0.25f, 0.5f}, {end, -0.25f, 0.0f}}, {{end, 0.5f, 0}, {-1, 0, -0.5f}}};
}
const std::vector<Uid> kRowFirst{0, Uid(kRowBoxes - 1)};

/// One segment cast as all hits, closest hit and any hit: the counters and the answers of each.
struct EachKind {
    Counters all, closest, any;
    HitLists every, nearest, some;
};
EachKind cast_each_kind(Structure& s, const Segment& ray) {
    const std::vector<Segment> one{ray};
    EachKind k;
    s.cast_counted(one, k.every, k.all);
    s.cast_counted(one, std::vector<QueryKind>{QueryKind::closest}, k.nearest, k.closest);
    s.cast_counted(one, std::vector<QueryKind>{QueryKind::any}, k.some, k.any);
    return k;
}

TEST(QueryKinds, TreesPruneClosestAndAnyAlongARowOfBoxes) {
    constexpr int kBoxes = kRowBoxes;
    const std::vector<Object> objects = row_of_boxes();
    const std::vector<Segment> rays = row_rays();
    const std::vector<Uid>& first = kRowFirst;
    for (const char* name : {"dbvh", "lbvh", "wbvh"}) {
        std::unique_ptr<Structure> s = find_structure(name).make(nlohmann::json::object(), "params");
        s->build(objects);
        s->commit();
        for (std::size_t r = 0; r < rays.size(); ++r) {
            const std::string where = std::string(name) + " ray " + std::to_string(r);
            const auto [all, closest, any, every, nearest, some] = cast_each_kind(*s, rays[r]);
            ASSERT_EQ(every.uids.size(), std::size_t(kBoxes)) << where;
            ASSERT_EQ(nearest.uids, std::vector<Uid>{first[r]}) << where;
            ASSERT_EQ(some.uids.size(), 1u) << where;
            // All hits test every box; the closest hit a few leaves' worth near the start.
            EXPECT_EQ(all.n_rb, std::uint64_t(kBoxes)) << where;
            EXPECT_LT(closest.n_rb * 16, all.n_rb) << where;
            EXPECT_LT(closest.n_t * 16, all.n_t) << where;
            EXPECT_LT(any.n_t * 16, all.n_t) << where;
        }
    }
}

/// The grids' walks go front to back and stop, for the closest hit, at the first cell entered
/// after the best hit, at every level of the hash grid; any hit stops at its first hit. Along the
/// row the first box lies in the first cell, so closest and any read a few cells and the boxes in
/// them where all hits reads every cell and box (counters, not time: deterministic). The hash grid
/// at depths 0..3 with capacities small enough for the cells to subdivide down to max_depth.
TEST(QueryKinds, GridsPruneClosestAndAnyAlongARowOfBoxes) {
    const std::vector<Object> objects = row_of_boxes();
    const std::vector<Segment> rays = row_rays();
    std::vector<std::pair<std::string, nlohmann::json>> configurations{{"ug", nlohmann::json::object()}};
    for (int depth = 0; depth <= 3; ++depth)
        configurations.emplace_back("hg", nlohmann::json{{"max_depth", depth}, {"max_capacity", 2}});
    for (const auto& [name, params] : configurations) {
        std::unique_ptr<Structure> s = find_structure(name).make(params, "params");
        s->build(objects);
        s->commit();
        if (name == "hg") {
            // Every level exists: the deepest cells hold a box or two each.
            const int depth = params["max_depth"].get<int>();
            EXPECT_EQ(s->stats()["max_depth_used"].get<int>(), depth) << s->stats().dump();
        }
        for (std::size_t r = 0; r < rays.size(); ++r) {
            const std::string where = name + ' ' + params.dump() + " ray " + std::to_string(r);
            const auto [all, closest, any, every, nearest, some] = cast_each_kind(*s, rays[r]);
            ASSERT_EQ(every.uids.size(), std::size_t(kRowBoxes)) << where;
            ASSERT_EQ(nearest.uids, std::vector<Uid>{kRowFirst[r]}) << where;
            ASSERT_EQ(some.uids.size(), 1u) << where;
            EXPECT_GE(all.n_rb, std::uint64_t(kRowBoxes)) << where;
            EXPECT_LT(closest.n_t * 4, all.n_t) << where;
            EXPECT_LT(closest.n_rb * 4, all.n_rb) << where;
            EXPECT_LT(any.n_t * 4, all.n_t) << where;
        }
    }
}

TEST(QueryKinds, SimulatorVerifiesEveryKindOnHardScenes) {
    for (const test::NamedScene& scene : test::hard_scenes()) {
        Recording r = scene.recording;
        std::uint32_t f = 0;
        for (Frame& frame : r.frames)
            frame.kinds = generate_kinds(frame.rays.size(), parse_query_mix("closest:2,any,all"), 5, ++f);
        for (const char* name : {"bf", "ug", "hg", "dbvh", "lbvh", "wbvh", "embree", "bullet_dbvt", "ode_quadtree",
                                 "ode_hash", "ode_sap"}) {
            const SimulationResult res =
                test::expect_matches_ground_truth(r, name, nlohmann::json::object(), scene.name);
            std::uint64_t closest = 0, rays = 0;
            for (const FrameResult& fr : res.frames) closest += fr.closest, rays += fr.rays;
            if (rays >= 8) {
                EXPECT_GT(closest, 0u) << scene.name;
            }
        }
    }
}

TEST(QueryKinds, VerificationFlagsWrongClosestAndAnyAnswers) {
    const GroundTruth truth(tie_objects());
    const std::vector<Segment> rays{tie_cases()[0].ray};
    const std::vector<QueryKind> closest{QueryKind::closest}, any{QueryKind::any};
    auto answer = [](std::vector<Uid> uids) {
        HitLists h;
        h.uids = std::move(uids);
        h.end_ray();
        return h;
    };
    // 3 and 7 tie at t = 0.25: either is within the tolerance; 9 lies clearly behind.
    EXPECT_EQ(truth.verify(rays, closest, answer({3})).mismatches(), 0u);
    EXPECT_EQ(truth.verify(rays, closest, answer({7})).mismatches(), 0u);
    EXPECT_EQ(truth.verify(rays, closest, answer({9})).missed, 1u);
    EXPECT_EQ(truth.verify(rays, closest, answer({})).missed, 1u);
    EXPECT_EQ(truth.verify(rays, closest, answer({3, 7})).extra, 1u);
    EXPECT_EQ(truth.verify(rays, closest, answer({1})).extra, 1u);  // clearly missed
    // Any: a met box farther along is right; a box never met is not.
    EXPECT_EQ(truth.verify(rays, any, answer({9})).mismatches(), 0u);
    EXPECT_EQ(truth.verify(rays, any, answer({1})).extra, 1u);
    EXPECT_EQ(truth.verify(rays, any, answer({})).missed, 1u);
    // Nothing to hit: none is the answer, for both kinds.
    const std::vector<Segment> miss{tie_cases()[6].ray};
    EXPECT_EQ(truth.verify(miss, closest, answer({})).mismatches(), 0u);
    EXPECT_EQ(truth.verify(miss, any, answer({})).mismatches(), 0u);
}

TEST(QueryKinds, QueryMixParsesAndRefusesBadInput) {
    const auto mix = parse_query_mix("closest:0.6,any:0.3,all:0.1");
    ASSERT_EQ(mix.size(), 3u);
    EXPECT_EQ(mix[0].kind, QueryKind::closest);
    EXPECT_EQ(mix[2].weight, 0.1);
    EXPECT_TRUE(asks_all_only(parse_query_mix("all")));
    EXPECT_TRUE(asks_all_only(parse_query_mix("all,closest:0")));
    EXPECT_FALSE(asks_all_only(mix));
    EXPECT_THROW(parse_query_mix("nearest"), InputError);
    EXPECT_THROW(parse_query_mix("closest:-1"), InputError);
    EXPECT_THROW(parse_query_mix("closest:0"), InputError);
    try {
        parse_query_mix("closest,first");
        FAIL();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("unknown kind 'first' (known: all, closest, any)"), std::string::npos);
    }
}

TEST(QueryKinds, KindsAreExactSharesAndLeaveRaysAndDynamicsAlone) {
    SceneSettings s = preset_settings("uni-s");
    s.frames = 4;
    s.rays.per_frame = 100;
    const Recording plain = generate_scene(s);
    s.rays.query_mix = parse_query_mix("all");
    EXPECT_EQ(encode_recording(generate_scene(s)), encode_recording(plain));  // bytes unchanged
    EXPECT_EQ(recording_version(plain), 1u);
    s.rays.query_mix = parse_query_mix("closest:0.6,any:0.3,all:0.1");
    const Recording mixed = generate_scene(s);
    EXPECT_EQ(recording_version(mixed), 3u);
    EXPECT_EQ(encode_recording(generate_scene(s)), encode_recording(mixed));  // same seed, same bytes
    ASSERT_EQ(mixed.frames.size(), plain.frames.size());
    for (std::size_t f = 0; f < mixed.frames.size(); ++f) {
        const Frame &a = mixed.frames[f], &b = plain.frames[f];
        EXPECT_EQ(a.rays, b.rays);
        EXPECT_EQ(a.inserts, b.inserts);
        EXPECT_EQ(a.removes, b.removes);
        EXPECT_EQ(a.moves, b.moves);
        ASSERT_EQ(a.kinds.size(), a.rays.size());
        std::size_t counts[kQueryKinds] = {};
        for (QueryKind k : a.kinds) ++counts[int(k)];
        EXPECT_EQ(counts[int(QueryKind::closest)], 60u);
        EXPECT_EQ(counts[int(QueryKind::any)], 30u);
        EXPECT_EQ(counts[int(QueryKind::all)], 10u);
    }
    EXPECT_NE(mixed.meta.find("\"query_mix\""), std::string::npos);
    EXPECT_EQ(plain.meta.find("query_mix"), std::string::npos);
}

TEST(QueryKinds, RecordingRoundTripsKindsAndValidatesThem) {
    SceneSettings s = preset_settings("uni-s");
    s.frames = 3;
    s.rays.per_frame = 20;
    s.rays.query_mix = parse_query_mix("closest,any");
    const Recording r = generate_scene(s);
    const std::string bytes = encode_recording(r);
    EXPECT_EQ(decode_recording(bytes, "r.rcbscene"), r);

    Recording bad = r;
    bad.frames[1].kinds.pop_back();
    EXPECT_THROW(refuse_invalid_recording(bad, "bad"), InputError);
    bad = r;
    bad.frames[0].kinds[0] = QueryKind(7);
    EXPECT_THROW(refuse_invalid_recording(bad, "bad"), InputError);
    // A kind byte out of range in a file (encode_recording writes what it is given).
    try {
        decode_recording(encode_recording(bad), "k.rcbscene");
        FAIL();
    } catch (const InputError& e) {
        EXPECT_NE(std::string(e.what()).find("k.rcbscene: frame 1: ray 0: unknown query kind 7"), std::string::npos)
            << e.what();
    }
    // The reader keeps no kinds for a frame whose rays are all `all`.
    Recording plain = r;
    plain.frames[2].kinds.assign(plain.frames[2].rays.size(), QueryKind::all);
    EXPECT_TRUE(decode_recording(encode_recording(plain), "p").frames[2].kinds.empty());
}

}  // namespace
}  // namespace rcb
