// Shapes, their tests against the double-precision truth, and the query levels (candidates, boxes,
// shapes) of every structure. The recording format's version 2: recording_test.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "core/base/error.h"
#include "core/truth/ground_truth.h"
#include "accel/narrow/narrow_phase.h"
#include "core/scene/recording_io.h"
#include "accel/registry.h"
#include "core/scene/shape.h"
#include "tests/test_scenes.h"

namespace rcb {
namespace {

Contact truth(const Segment& s, const Shape& shape) {
    return classify_shape_contact(Segmentd{s.p0.as<double>(), s.p1.as<double>()}, shape);
}

bool narrow(const Segment& s, const Shape& shape) { return segment_hits_shape(s, shape); }

const Shape kTri = Shape::triangle({0, 0, 0}, {1, 0, 0}, {0, 1, 0});

TEST(Shapes, TriangleFaceEdgeVertexAndPlane) {
    // Through the face, squarely: both say hit.
    const Segment face{{0.25f, 0.25f, -1}, {0.25f, 0.25f, 1}};
    EXPECT_EQ(truth(face, kTri), Contact::hit);
    EXPECT_TRUE(narrow(face, kTri));
    float t = -1;
    EXPECT_TRUE(segment_hits_shape(face, kTri, &t));
    EXPECT_FLOAT_EQ(t, 0.5f);
    // Beside it: both say miss.
    const Segment beside{{0.75f, 0.75f, -1}, {0.75f, 0.75f, 1}};
    EXPECT_EQ(truth(beside, kTri), Contact::miss);
    EXPECT_FALSE(narrow(beside, kTri));
    // Through an edge or a vertex, or along the plane: a touch, either answer is right.
    EXPECT_EQ(truth(Segment{{0.5f, 0, -1}, {0.5f, 0, 1}}, kTri), Contact::touch);
    EXPECT_EQ(truth(Segment{{0, 0, -1}, {0, 0, 1}}, kTri), Contact::touch);
    EXPECT_EQ(truth(Segment{{-1, 0.2f, 0}, {2, 0.2f, 0}}, kTri), Contact::touch);
    // Ending on the face is a touch; stopping short of it a miss.
    EXPECT_EQ(truth(Segment{{0.25f, 0.25f, -1}, {0.25f, 0.25f, 0}}, kTri), Contact::touch);
    EXPECT_EQ(truth(Segment{{0.25f, 0.25f, -1}, {0.25f, 0.25f, -0.5f}}, kTri), Contact::miss);
    EXPECT_FALSE(narrow(Segment{{0.25f, 0.25f, -1}, {0.25f, 0.25f, -0.5f}}, kTri));
}

TEST(Shapes, WatertightAcrossASharedEdge) {
    // Two triangles sharing the diagonal of the unit square: a segment through the diagonal hits
    // at least one of them, however float rounds (Woop et al. 2013).
    const Shape a = Shape::triangle({0, 0, 0}, {1, 0, 0}, {1, 1, 0});
    const Shape b = Shape::triangle({0, 0, 0}, {1, 1, 0}, {0, 1, 0});
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> u(0.0f, 1.0f), tilt(-0.3f, 0.3f);
    for (int i = 0; i < 2000; ++i) {
        const float x = u(rng);
        const Vec3 on{x, x, 0}, d{tilt(rng), tilt(rng), 1};
        const Segment s{on - d, on + d};
        EXPECT_TRUE(narrow(s, a) || narrow(s, b)) << "a segment slipped through the shared edge at x = " << x;
    }
}

TEST(Shapes, DegenerateTriangleIsNeverAMustHit) {
    const Shape line = Shape::triangle({0, 0, 0}, {1, 0, 0}, {2, 0, 0});
    EXPECT_NE(truth(Segment{{0.5f, 0, -1}, {0.5f, 0, 1}}, line), Contact::hit);
    EXPECT_EQ(truth(Segment{{0.5f, 3, -1}, {0.5f, 3, 1}}, line), Contact::miss);
    EXPECT_FALSE(narrow(Segment{{0.5f, 3, -1}, {0.5f, 3, 1}}, line));
}

TEST(Shapes, RotatedBoxCutsTheCornersOfItsBounds) {
    // A unit cube turned 45° about z: its bounds reach x = ±√2/2, the box itself not near the
    // corners of the bounds.
    const float half_angle = float(M_PI / 8);  // q = (cos θ/2, sin θ/2 · axis), θ = 45°
    const Shape obb = Shape::obb({0, 0, 0}, {0.5f, 0.5f, 0.5f}, {std::cos(half_angle), 0, 0, std::sin(half_angle)});
    const Aabb bounds = shape_bounds(obb);
    EXPECT_NEAR(bounds.max.x, std::sqrt(0.5), 1e-6);
    EXPECT_LE(bounds.min.x, -0.7071f);
    const Segment corner{{0.6f, 0.6f, -1}, {0.6f, 0.6f, 1}};  // inside the bounds, outside the box
    EXPECT_TRUE(segment_hits_box(corner, bounds));
    EXPECT_EQ(truth(corner, obb), Contact::miss);
    EXPECT_FALSE(narrow(corner, obb));
    const Segment centre{{0.1f, 0.1f, -1}, {0.1f, 0.1f, 1}};
    EXPECT_EQ(truth(centre, obb), Contact::hit);
    EXPECT_TRUE(narrow(centre, obb));
    // A zero-thickness box crossed squarely is hit.
    const Shape flat = Shape::obb({0, 0, 0}, {1, 1, 0}, {1, 0, 0, 0});
    EXPECT_EQ(truth(Segment{{0.2f, 0.3f, -1}, {0.2f, 0.3f, 1}}, flat), Contact::hit);
    EXPECT_TRUE(narrow(Segment{{0.2f, 0.3f, -1}, {0.2f, 0.3f, 1}}, flat));
}

TEST(Shapes, SpheresAndCapsules) {
    const Shape ball = Shape::sphere({0, 0, 0}, 1);
    EXPECT_EQ(truth(Segment{{-2, 0.5f, 0}, {2, 0.5f, 0}}, ball), Contact::hit);
    EXPECT_EQ(truth(Segment{{-2, 0.9f, 0.9f}, {2, 0.9f, 0.9f}}, ball), Contact::miss);  // in the bounds' corner
    EXPECT_FALSE(narrow(Segment{{-2, 0.9f, 0.9f}, {2, 0.9f, 0.9f}}, ball));
    EXPECT_EQ(truth(Segment{{-2, 1, 0}, {2, 1, 0}}, ball), Contact::touch);  // tangent
    float t = -1;
    EXPECT_TRUE(segment_hits_shape(Segment{{-2, 0, 0}, {2, 0, 0}}, ball, &t));
    EXPECT_NEAR(t, 0.25f, 1e-5);
    const Shape pill = Shape::capsule({0, 0, 0}, {4, 0, 0}, 0.5f);
    EXPECT_EQ(truth(Segment{{2, -1, 0.3f}, {2, 1, 0.3f}}, pill), Contact::hit);
    EXPECT_EQ(truth(Segment{{4.45f, -1, 0.45f}, {4.45f, 1, 0.45f}}, pill), Contact::miss);  // beyond the cap
    EXPECT_FALSE(narrow(Segment{{4.45f, -1, 0.45f}, {4.45f, 1, 0.45f}}, pill));
}

/// Random shapes and segments (many near-grazing): the float narrow phase never contradicts a
/// "must" of the double-precision truth.
TEST(Shapes, NarrowPhaseAgreesWithTheTruthOnRandomCases) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> pos(-100.0f, 100.0f), size(0.0f, 5.0f), unit(-1.0f, 1.0f);
    int hits = 0, misses = 0;
    for (int i = 0; i < 20000; ++i) {
        const Vec3 c{pos(rng), pos(rng), pos(rng)};
        Shape shape;
        switch (i % 4) {
            case 0:
                shape = Shape::triangle(c, c + Vec3{size(rng), size(rng), size(rng)},
                                        c + Vec3{size(rng), -size(rng), size(rng)});
                break;
            case 1:
                shape = Shape::obb(c, {size(rng), size(rng), size(rng)}, {unit(rng), unit(rng), unit(rng), unit(rng)});
                break;
            case 2:
                shape = Shape::sphere(c, size(rng));
                break;
            default:
                shape = Shape::capsule(c, c + Vec3{size(rng), size(rng), size(rng)}, size(rng) * 0.3f);
        }
        // Segments towards a point near the shape's bounds, some ending short of it.
        const Aabb b = shape_bounds(shape);
        const Vec3 target = b.center() + Vec3{unit(rng), unit(rng), unit(rng)} * (0.6f * b.longest_edge());
        const Vec3 from = target + Vec3{unit(rng), unit(rng), unit(rng)} * 20.0f;
        const Segment s{from, from + (target - from) * (1.0f + unit(rng))};
        const Contact want = truth(s, shape);
        const bool got = narrow(s, shape);
        if (want == Contact::hit) {
            EXPECT_TRUE(got) << shape_name(shape.kind) << " case " << i;
        }
        if (want == Contact::miss) {
            EXPECT_FALSE(got) << shape_name(shape.kind) << " case " << i;
        }
        hits += want == Contact::hit;
        misses += want == Contact::miss;
    }
    EXPECT_GT(hits, 2000);  // the cases exercise both answers
    EXPECT_GT(misses, 2000);
}

/// The narrow phase against the truth at every magnitude the format allows (coordinates up to
/// ±1e15), shapes from 1e-5 of the magnitude to a tenth of it, long segments from far away
/// through points near (and on) the shape, half the capsules' segments nearly along the axis:
/// where a float closest-point test cancels or overflows.
TEST(Shapes, NarrowPhaseAgreesWithTheTruthAtEveryScale) {
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> unit(-1.0, 1.0), one(0.0, 1.0), exponent(-4.0, 0.0), tilt(-1e-3, 1e-3);
    auto random_unit = [&] {
        Vec3d d{unit(rng), unit(rng), unit(rng)};
        return d * (1 / std::sqrt(dot(d, d) + 1e-300));
    };
    for (int e = 0; e <= 15; ++e) {
        const double scale = std::pow(10.0, e);
        SCOPED_TRACE("coordinates ~1e" + std::to_string(e));
        std::array<int, kShapeKinds> hits{}, misses{};
        for (int i = 0; i < 4000; ++i) {
            Vec3d c;  // between 0.2 and 0.4 scale per axis, either sign
            for (int a = 0; a < 3; ++a) c[a] = (unit(rng) < 0 ? -1 : 1) * scale * (0.3 + 0.1 * unit(rng));
            const double size = 0.1 * scale * std::pow(10.0, exponent(rng));
            const Vec3d u = random_unit();
            Shape shape;
            Vec3d target;  // a point in, on or near the shape
            switch (i % 4) {
                case 0: {
                    const Vec3d b = c + random_unit() * size, d = c + random_unit() * size;
                    shape = Shape::triangle(c.as<float>(), b.as<float>(), d.as<float>());
                    const double x = one(rng) * 0.7, y = one(rng) * 0.7;
                    target = c + (b - c) * x + (d - c) * y;
                    break;
                }
                case 1:
                    shape = Shape::obb(c.as<float>(), (Vec3d{one(rng), one(rng), one(rng)} * size).as<float>(),
                                       {float(unit(rng)), float(unit(rng)), float(unit(rng)), float(unit(rng))});
                    target = c + random_unit() * (size * 1.5 * one(rng));
                    break;
                case 2:
                    shape = Shape::sphere(c.as<float>(), float(size));
                    target = c + random_unit() * (size * 1.5 * one(rng));
                    break;
                default: {
                    const double radius = size * std::pow(10.0, exponent(rng));
                    shape = Shape::capsule(c.as<float>(), (c + u * size).as<float>(), float(radius));
                    target = c + u * (size * (1.2 * one(rng) - 0.1)) + random_unit() * (radius * 2 * one(rng));
                }
            }
            ASSERT_EQ(shape_problem(shape, 1e15), "") << "case " << i;
            const Vec3d dir = i % 8 == 3 ? (u + Vec3d{tilt(rng), tilt(rng), tilt(rng)}) : random_unit();
            const Vec3d from = target - dir * (0.4 * scale * (0.5 + 0.5 * one(rng)));
            const Segment s{from.as<float>(), (from + (target - from) * (1.0 + unit(rng))).as<float>()};
            const Contact want = truth(s, shape);
            const bool got = narrow(s, shape);
            if (want == Contact::hit) {
                EXPECT_TRUE(got) << shape_name(shape.kind) << " case " << i << " missed";
            }
            if (want == Contact::miss) {
                EXPECT_FALSE(got) << shape_name(shape.kind) << " case " << i << " hit, the truth is a miss";
            }
            hits[int(shape.kind)] += want == Contact::hit;
            misses[int(shape.kind)] += want == Contact::miss;
        }
        for (int k = 1; k < kShapeKinds; ++k) {  // both answers are exercised for every kind (of ~1000 cases)
            EXPECT_GT(hits[k], 40) << shape_name(ShapeKind(k));
            EXPECT_GT(misses[k], 40) << shape_name(ShapeKind(k));
        }
    }
}

/// Capsules at 1e11-1e12 whose answer a float closest-point test got wrong: a segment 2e11 away
/// reported as a hit (the denominator overflowed to NaN), and one 1.8e7 from an axis of radius
/// 5.5e7, nearly along it, reported as a miss (the denominator cancelled).
TEST(Shapes, CapsulesAtLargeCoordinates) {
    const Shape thin = Shape::capsule({2.88819872e+11f, -2.5212579e+11f, -2.13571256e+11f},
                                      {2.8897683e+11f, -2.51936113e+11f, -2.13435302e+11f}, 17078822.0f);
    const Segment far{{1.58959583e+11f, -4.09146262e+11f, -3.25959942e+11f},
                      {1.76768041e+11f, -3.87612901e+11f, -3.10547612e+11f}};
    ASSERT_EQ(truth(far, thin), Contact::miss);
    EXPECT_FALSE(narrow(far, thin));
    const Shape thick = Shape::capsule({-2.27016114e+11f, -2.96937652e+11f, 3.04662479e+11f},
                                       {-2.82998637e+11f, -3.36413262e+11f, 3.32195103e+11f}, 55192436.0f);
    const Segment along{{9.29877504e+09f, -1.30828739e+11f, 1.88307685e+11f},
                        {-3.05622319e+11f, -3.52257114e+11f, 3.43322657e+11f}};
    ASSERT_EQ(truth(along, thick), Contact::hit);
    EXPECT_TRUE(narrow(along, thick));
    float t = -1;
    EXPECT_TRUE(segment_hits_shape(along, thick, &t));
    EXPECT_GT(t, 0.0f);
    EXPECT_LE(t, 1.0f);
}

TEST(Shapes, BadParametersAreNamed) {
    Shape nan = kTri;
    nan.v[4] = std::nanf("");
    EXPECT_NE(shape_problem(nan, 1e15).find("non-finite"), std::string::npos);
    Shape spin = Shape::obb({0, 0, 0}, {1, 1, 1}, {1, 0, 0, 0});
    spin.v[6] = 2;  // |q| = 2: not a rotation
    EXPECT_NE(shape_problem(spin, 1e15).find("unit quaternion"), std::string::npos);
    EXPECT_NE(shape_problem(Shape::sphere({0, 0, 0}, -1), 1e15).find("negative radius"), std::string::npos);
    EXPECT_NE(shape_problem(Shape::sphere({1e15f, 0, 0}, 1e14f), 1e15).find("beyond"), std::string::npos);
    EXPECT_EQ(shape_problem(Shape::obb({0, 0, 0}, {1, 0, 1}, {1, 0, 0, 0}), 1e15), "");  // zero thickness is fine
}

Recording shaped_recording() {
    Recording r = test::generated_scene("irregular", 300, 4, 5);
    return test::with_shapes(r, 9);
}

/// Every structure and peer at every level on a scene of mixed shapes: the shapes level is exact
/// against the shapes' truth, the candidate level a superset of the box level, the box level exact.
TEST(QueryLevels, EveryStructureKeepsItsContract) {
    const Recording r = shaped_recording();
    for (const StructureInfo& info : structure_registry()) {
        SCOPED_TRACE(info.name);
        const SimulationResult boxes = test::expect_matches_ground_truth(r, info.name, {{"query", "boxes"}});
        const SimulationResult shapes = test::expect_matches_ground_truth(r, info.name, {{"query", "shapes"}});
        const SimulationResult candidates = test::expect_matches_ground_truth(r, info.name, {{"query", "candidates"}});
        std::uint64_t box_hits = 0, shape_hits = 0, candidate_hits = 0;
        for (std::size_t f = 0; f < boxes.frames.size(); ++f) {
            box_hits += boxes.frames[f].hits;
            shape_hits += shapes.frames[f].hits;
            candidate_hits += candidates.frames[f].hits;
            EXPECT_EQ(shapes.frames[f].precision(), 1.0);
            EXPECT_EQ(shapes.frames[f].recall(), 1.0);
            EXPECT_EQ(boxes.frames[f].recall(), 1.0);
            EXPECT_EQ(candidates.frames[f].recall(), 1.0);
            EXPECT_LE(candidates.frames[f].precision(), boxes.frames[f].precision());
            EXPECT_GT(shapes.frames[f].counters.n_ro, 0u);
            EXPECT_EQ(shapes.frames[f].counters.n_ro - shapes.frames[f].counters.n_ro_hits,
                      boxes.frames[f].hits - shapes.frames[f].hits);  // N_BFP: box hit, shape missed
        }
        EXPECT_LT(shape_hits, box_hits);  // the shapes are tighter than their boxes
        EXPECT_GE(candidate_hits, box_hits);
        EXPECT_FALSE(boxes.params.contains("query"));  // the default level is not recorded
        EXPECT_EQ(shapes.params.at("query"), "shapes");
    }
}

TEST(QueryLevels, CandidatesAreASupersetOnTheHardScenes) {
    for (const test::NamedScene& scene : test::hard_scenes())
        for (const StructureInfo& info : structure_registry()) {
            SCOPED_TRACE(scene.name + " / " + info.name);
            test::expect_matches_ground_truth(scene.recording, info.name, {{"query", "candidates"}}, scene.name);
        }
}

/// Tighter volumes: every level keeps its contract (a box-level answer through a k-DOP or obb lies
/// between the shapes' hits and the boxes'), and each volume cuts the bounding-volume false
/// positives (N_BFP) of the narrow phase.
TEST(LeafVolumes, TighterVolumesKeepTheContractAndCutFalsePositives) {
    const Recording r = shaped_recording();
    for (const char* structure : {"dbvh", "lbvh", "wbvh", "ug", "embree"}) {
        SCOPED_TRACE(structure);
        const SimulationResult plain = test::expect_matches_ground_truth(r, structure, {{"query", "shapes"}});
        std::uint64_t plain_bfp = 0;
        for (const FrameResult& f : plain.frames) plain_bfp += f.counters.n_bfp();
        ASSERT_GT(plain_bfp, 0u);
        for (const char* bv : {"kdop14", "kdop18", "obb"}) {
            SCOPED_TRACE(bv);
            const SimulationResult tight =
                test::expect_matches_ground_truth(r, structure, {{"query", "shapes"}, {"leaf_bv", bv}});
            test::expect_matches_ground_truth(r, structure, {{"query", "boxes"}, {"leaf_bv", bv}});
            std::uint64_t tight_bfp = 0;
            for (std::size_t f = 0; f < tight.frames.size(); ++f) {
                tight_bfp += tight.frames[f].counters.n_bfp();
                EXPECT_EQ(tight.frames[f].hits, plain.frames[f].hits);
            }
            EXPECT_LT(tight_bfp, plain_bfp);
            EXPECT_EQ(tight.params.at("leaf_bv"), bv);
        }
    }
}

TEST(LeafVolumes, VolumesContainTheirShapes) {
    // A segment that must hit a shape must hit its volume, on random shapes and segments.
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> pos(-50.0f, 50.0f), size(0.0f, 4.0f), unit(-1.0f, 1.0f);
    int tested = 0;
    for (int i = 0; i < 5000; ++i) {
        const Vec3 c{pos(rng), pos(rng), pos(rng)};
        const Shape shape =
            i % 3 == 0 ? Shape::triangle(c, c + Vec3{size(rng), size(rng), -size(rng)},
                                         c + Vec3{-size(rng), size(rng), size(rng)})
            : i % 3 == 1
                ? Shape::obb(c, {size(rng), size(rng), size(rng)}, {unit(rng), unit(rng), unit(rng), unit(rng)})
                : Shape::capsule(c, c + Vec3{size(rng), size(rng), size(rng)}, 0.3f * size(rng));
        const Object o = shaped_object(1, shape);
        const Vec3 target = o.box.center() + Vec3{unit(rng), unit(rng), unit(rng)} * (0.5f * o.box.longest_edge());
        const Vec3 from = target + Vec3{unit(rng), unit(rng), unit(rng)} * 10.0f;
        const Segment seg{from, from + (target - from) * 2.0f};
        if (truth(seg, shape) != Contact::hit) continue;
        ++tested;
        for (LeafBv bv : {LeafBv::kdop14, LeafBv::kdop18, LeafBv::obb})
            EXPECT_TRUE(segment_hits_volume(seg, o.box, leaf_volume(o, bv))) << "case " << i << " bv " << int(bv);
    }
    EXPECT_GT(tested, 500);
}

/// Every leaf volume of every structure, at the box and the shape level, keeps every hit of the
/// hard scenes with shapes: zero-volume shapes (points, lines) are crossed squarely by rays, and a
/// k-DOP test in float lost such a crossing by a rounding (found in lbvh and wbvh; every structure
/// shares the volume test). Long: every structure x hard scene x leaf volume x query level against the truth.
TEST(LeafVolumes, EveryLeafVolumeKeepsEveryHitOnTheHardScenes) {
    std::vector<test::NamedScene> scenes = test::hard_scenes();
    for (test::NamedScene& s : scenes) s.recording = test::with_shapes(s.recording, 3);
    for (const StructureInfo& info : structure_registry()) {
        const auto spec = std::find_if(info.params.begin(), info.params.end(),
                                       [](const ParamSpec& p) { return p.name == "leaf_bv"; });
        ASSERT_NE(spec, info.params.end()) << info.name;
        for (const test::NamedScene& s : scenes)
            for (const std::string& bv : spec->choices)
                for (const char* query : {"boxes", "shapes"}) {
                    SCOPED_TRACE(s.name + " / " + info.name + " / " + bv + " / " + query);
                    test::expect_matches_ground_truth(s.recording, info.name, {{"query", query}, {"leaf_bv", bv}},
                                                      s.name);
                }
    }
}

TEST(LeafVolumes, CandidatesTakeNoVolume) {
    test::expect_input_error(
        [] {
            find_structure("dbvh").make({{"query", "candidates"}, {"leaf_bv", "kdop14"}}, "structures[0].params");
        },
        "structures[0].params.leaf_bv");
    EXPECT_THROW(find_structure("bf").make({{"leaf_bv", "kdop26"}}, "params"), InputError);
}

/// The peers as shipped (no padding) promise no hit: the contract checks only that nothing is
/// invented, and whatever they lose shows as recall.
TEST(Robustness, PeersWithoutPaddingAreMeasuredNotTrusted) {
    EXPECT_FALSE(contract_of({{"robust", false}}).lower.has_value());
    EXPECT_TRUE(contract_of({{"robust", true}}).lower.has_value());
    for (const test::NamedScene& scene : test::hard_scenes())
        for (const char* peer : {"embree", "bullet_dbvt"}) {
            SCOPED_TRACE(scene.name + " / " + peer);
            const SimulationResult res =
                test::expect_matches_ground_truth(scene.recording, peer, {{"robust", false}}, scene.name);
            for (const FrameResult& f : res.frames) EXPECT_LE(f.recall(), 1.0);
        }
}

}  // namespace
}  // namespace rcb
