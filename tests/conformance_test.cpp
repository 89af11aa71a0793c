// Every registered structure, the registry iterated (no names here), through the conformance suite
// a program outside rcbench runs on its own structure (testing/conformance.h): exactness against
// the double-precision ground truth on the hard scenes, every ray as all, closest and any hit, at
// the defaults and at parameter sets drawn from its own ParamSpecs; the fuzz scene at the
// differential fuzzer's settings; check() after the build and after every frame; the refusal of
// bad parameters. The seed is printed on failure; RCB_CONFORMANCE_SEED=<n> draws other sets.
// Then the suite seen to fail: a structure that drops the last hit of its leaf is caught, naming
// the scene, the ray and the missing uid, and a factory that accepts any parameter is caught too.
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <cctype>
#include <functional>
#include <span>
#include <tuple>
#include <string>
#include <vector>

#include "accel/registry.h"
#include "accel/interface/structure.h"
#include "testing/conformance.h"
#include "tests/forwarding_structure.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

using test::kConformanceDraws, test::kConformanceFuzzFrames;

std::vector<std::string> registered_names() {
    std::vector<std::string> names;
    for (const StructureInfo& info : structure_registry()) names.push_back(info.name);
    return names;
}

class Conformance : public ::testing::TestWithParam<std::string> {};

TEST_P(Conformance, MatchesTheGroundTruthOnTheHardScenesForEveryQueryKind) {
    test::expect_exact_on_hard_scenes(find_structure(GetParam()));
}

TEST_P(Conformance, MatchesTheGroundTruthAtRandomParameters) {
    test::expect_exact_at_random_params(find_structure(GetParam()), test::conformance_seed(), kConformanceDraws);
}

TEST_P(Conformance, MatchesTheGroundTruthOnTheFuzzScene) {
    test::expect_exact_under_fuzz(find_structure(GetParam()), test::conformance_seed(), kConformanceFuzzFrames);
}

TEST_P(Conformance, RefusesBadParameters) { test::expect_refuses_bad_params(find_structure(GetParam())); }

/// A test name from a structure name: letters, digits and '_' (registered names may hold '-').
std::string test_name(const ::testing::TestParamInfo<std::string>& info) {
    std::string name = info.param;
    for (char& c : name)
        if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
    return name;
}

INSTANTIATE_TEST_SUITE_P(Registry, Conformance, ::testing::ValuesIn(registered_names()), test_name);

/// A leaf loop that stops one short: the toy list (test_support.h) in one leaf of `block` objects
/// per block, the last hit of each ray's traversal never reported. What the suite must catch.
class DropsLastHit : public test::Forwarding<DropsLastHit, test::ToyList> {
public:
    struct Params {
        int block = 64;
        static constexpr auto fields() { return std::tuple{Field{"block", &Params::block, 1, 64, "objects per leaf"}}; }
    };
    explicit DropsLastHit(const Params& p) : Forwarding(test::ToyList::Params{p.block, false}) {}

    template <class Count, class Visit>
    void traverse(const Segment& s, Count& count, Visit&& visit) {
        bool held = false;
        Uid held_uid = 0;
        float held_t = 0;
        inner_.traverse(s, count, [&](Uid uid, float t) {
            const bool go_on = !held || visit(held_uid, held_t);
            held = true, held_uid = uid, held_t = t;
            return go_on;
        });
    }
};

/// Described but not registered: the suite's checks take the entry itself, and a registered broken
/// structure would join every list the registry makes for the tests that run after these.
const StructureInfo& drops_last_hit() {
    static const StructureInfo info =
        describe_structure<DropsLastHit>("conformance_drops_last_hit", "drops the last hit of its leaf");
    return info;
}

/// The GoogleTest failures `check` reports, caught instead of failing this test.
std::vector<std::string> failures_of(const std::function<void()>& check) {
    ::testing::TestPartResultArray results;
    {
        ::testing::ScopedFakeTestPartResultReporter catcher(
            ::testing::ScopedFakeTestPartResultReporter::INTERCEPT_ONLY_CURRENT_THREAD, &results);
        check();
    }
    std::vector<std::string> out;
    for (int i = 0; i < results.size(); ++i)
        if (results.GetTestPartResult(i).failed()) out.push_back(results.GetTestPartResult(i).message());
    return out;
}

TEST(ConformanceSuite, NamesTheSceneRayAndMissingUidOfABrokenStructure) {
    Recording r;
    r.initial = {{7, {{-1, -1, -1}, {1, 1, 1}}}, {9, {{4, -1, -1}, {5, 1, 1}}}};
    r.frames.resize(1);
    r.frames[0].rays = {{{-3, 0, 0}, {3, 0, 0}}, {{-3, 0, 0}, {8, 0, 0}}};
    const std::string failures =
        test::ground_truth_failures(r, drops_last_hit(), nlohmann::json::object(), "two-boxes");
    EXPECT_NE(failures.find("conformance_drops_last_hit {} on scene two-boxes: 2 mismatches"), std::string::npos)
        << failures;
    EXPECT_NE(failures.find("scene two-boxes frame 1 ray 0 (all) from (-3, 0, 0) to (3, 0, 0): missed uid 7"),
              std::string::npos)
        << failures;
    EXPECT_NE(failures.find("scene two-boxes frame 1 ray 1 (all) from (-3, 0, 0) to (8, 0, 0): missed uid 9"),
              std::string::npos)
        << failures;
}

TEST(ConformanceSuite, FailsABrokenStructureOnEveryCheckOfExactness) {
    const std::vector<std::string> hard = failures_of([] { test::expect_exact_on_hard_scenes(drops_last_hit()); });
    ASSERT_FALSE(hard.empty());
    bool names_all = false;
    for (const std::string& f : hard) names_all |= f.find("on scene identical") != std::string::npos;
    EXPECT_TRUE(names_all) << hard.front();
    EXPECT_NE(hard.front().find("missed uid"), std::string::npos) << hard.front();
    for (const char* kind : {"(all)", "(closest)", "(any)"}) {
        bool seen = false;
        for (const std::string& f : hard) seen |= f.find(kind) != std::string::npos;
        EXPECT_TRUE(seen) << kind;
    }
    EXPECT_FALSE(
        failures_of([] { test::expect_exact_under_fuzz(drops_last_hit(), 1, kConformanceFuzzFrames); }).empty());
    EXPECT_FALSE(failures_of([] { test::expect_exact_at_random_params(drops_last_hit(), 1, 1); }).empty());
    // Its parameters are read by params_from_json: the refusals pass.
    EXPECT_EQ(test::refusal_failures(drops_last_hit()), "");
}

TEST(ConformanceSuite, FailsAFactoryThatAcceptsAnyParameter) {
    StructureInfo lax = find_structure("bf");
    const auto make = lax.make;
    lax.make = [make](const nlohmann::json&, const std::string& path) { return make({}, path); };
    const std::string failures = test::refusal_failures(lax);
    EXPECT_NE(failures.find("bf: accepted {\"no_such_parameter\":1}"), std::string::npos) << failures;
    EXPECT_NE(failures.find("bf: accepted {\"cast_threads\":0.0}"), std::string::npos) << failures;
}

}  // namespace
}  // namespace rcb
