// register_structure: a program's own structure joins the registry without editing registry.cpp,
// runs through the simulator and the differential check, and bad registrations are refused.
#include <gtest/gtest.h>

#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/base/error.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "tests/test_scenes.h"
#include "tests/test_support.h"

namespace rcb {
namespace {

/// Registered once per process (the registry is global). The address of bf's entry is taken just
/// before, to check that registering moves no existing entry.
struct Registered {
    const StructureInfo* bf_before;
    const StructureInfo* list_scan;
};
const Registered& registered() {
    static const Registered r = [] {
        const StructureInfo* bf = &find_structure("bf");
        return Registered{
            bf, &register_structure<test::ToyList>("test_list_scan", "a list scanned per ray (registry_test)")};
    }();
    return r;
}

const auto error_of = test::input_error_of;

TEST(Registry, UnknownStructureListsTheKnownOnes) {
    const std::string m = test::input_error_of([] { find_structure("kdtree"); });
    EXPECT_EQ(m.find("unknown structure 'kdtree' (known: bf"), 0u) << m;
    EXPECT_EQ(find_structure("bf").name, "bf");
}

TEST(RegisterStructure, JoinsTheRegistryAfterTheBuiltIns) {
    const Registered& r = registered();
    EXPECT_EQ(&find_structure("test_list_scan"), r.list_scan);
    EXPECT_EQ(r.list_scan->name, "test_list_scan");
    EXPECT_EQ(r.list_scan->summary, "a list scanned per ray (registry_test)");
    // Without an origin and a family, a program's structure is its own and of no family rcbench
    // filters by (findings compare it; it is in no "every grid" or "every BVH" list).
    EXPECT_EQ(r.list_scan->origin, Origin::own);
    EXPECT_EQ(r.list_scan->family, Family::other);
    EXPECT_EQ(structure_registry().front().name, "bf");
    EXPECT_EQ(&find_structure("bf"), r.bf_before) << "registering moved an existing entry";
    bool listed = false;
    for (const StructureInfo& info : structure_registry()) listed |= &info == r.list_scan;
    EXPECT_TRUE(listed);
}

// A structure written for the last release overrides validate(), check()'s old name, and no
// check(): for this release check() calls it, so the simulator's checks and the conformance suite
// still reach its invariants.
class LastReleaseStructure final : public Structure {
public:
    void build(std::span<const Object>) override {}
    void insert(const Object&) override {}
    void remove(Uid) override {}
    void move(const Object&) override {}
    using Structure::cast;
    void cast(std::span<const Segment>, std::span<const QueryKind>, HitLists&) override {}
    void cast_counted(std::span<const Segment>, std::span<const QueryKind>, HitLists&, Counters&) override {}
    std::optional<Hit> cast_closest(const Segment&) override { return std::nullopt; }
    bool cast_any(const Segment&) override { return false; }
    void set_candidates_only(bool) override {}
    std::size_t size() const override { return 0; }
    std::size_t memory_bytes() const override { return 0; }
    void validate() const override { broken_invariant("last_release", "its own validate() ran"); }
};

TEST(RegisterStructure, CheckCallsTheOldNameOfAStructureOfTheLastRelease) {
    const LastReleaseStructure s;
    try {
        s.check();
        FAIL() << "check() did not call validate()";
    } catch (const std::logic_error& e) {
        EXPECT_STREQ(e.what(), "last_release: its own validate() ran");
    }
}

TEST(RegisterStructure, RunsThroughTheSimulatorAndMatchesTheGroundTruth) {
    registered();
    const Recording r = test::generated_scene("irregular", 1200, 5, 31, 0.1);
    SimulationOptions o;
    o.check = true;
    const SimulationResult res = simulate(r, find_structure("test_list_scan"), nlohmann::json::object(), o);
    EXPECT_TRUE(res.verified);
    EXPECT_EQ(res.structure, "test_list_scan");
    ASSERT_EQ(res.frames.size(), 5u);
    EXPECT_EQ(res.mismatches(), 0u);
    std::uint64_t hits = 0;
    for (const FrameResult& f : res.frames) hits += f.hits;
    EXPECT_GT(hits, 0u);
    for (const test::NamedScene& s : test::hard_scenes())
        test::expect_matches_ground_truth(s.recording, "test_list_scan", {}, s.name);
}

TEST(RegisterStructure, ParamsOfARegisteredStructureAreChecked) {
    registered();
    EXPECT_EQ(error_of([] {
                  find_structure("test_list_scan").make({{"cells", 4}}, "--param");
              }),
              "--param.cells: unknown parameter of test_list_scan (known: block, backwards, query, leaf_bv)");
}

TEST(RegisterStructure, RefusesDuplicateAndBadNames) {
    registered();
    const std::size_t before = structure_registry().size();
    EXPECT_EQ(
        error_of([] {
            register_structure<test::ToyList>("bf", "mine");
        }).rfind("register_structure('bf'): a structure named 'bf' is already registered ('brute force: every", 0),
        0u);
    EXPECT_NE(error_of([] {
                  register_structure<test::ToyList>("test_list_scan", "again");
              }).find("register_structure('test_list_scan'): a structure named 'test_list_scan' is already registered"),
              std::string::npos);
    for (const std::string& name :
         std::vector<std::string>{"", "has space", "a/b", "caf\xc3\xa9", std::string(65, 'x')})
        EXPECT_NE(error_of([&] {
                      register_structure<test::ToyList>(name, "x");
                  }).find("a structure name is 1 to 64 ASCII letters, digits, '_' or '-'"),
                  std::string::npos)
            << name;
    EXPECT_EQ(error_of([] { register_structure<test::ToyList>("all", "x"); }),
              "register_structure('all'): 'all' is reserved (rcbench simulate --structure all runs every structure)");
    EXPECT_EQ(structure_registry().size(), before);
}

TEST(RegisterStructure, RefusesAnEntryWithoutFactoryOrWithABadDefault) {
    const std::size_t before = structure_registry().size();
    StructureInfo no_factory;
    no_factory.name = "test_no_factory";
    EXPECT_EQ(error_of([&] { register_structure(no_factory); }),
              "register_structure('test_no_factory'): the entry has no factory (make is empty)");

    StructureInfo bad_default = describe_structure<test::ToyList>("test_bad_default", "x");
    ParamSpec cells;
    cells.name = "cells";
    cells.kind = ParamKind::integer;
    cells.lo = 1;
    cells.hi = 8;
    cells.default_value = 0;
    bad_default.params.push_back(cells);
    EXPECT_NE(error_of([&] {
                  register_structure(bad_default);
              }).find("register_structure('test_bad_default'): default params"),
              std::string::npos)
        << error_of([&] { register_structure(bad_default); });
    EXPECT_EQ(structure_registry().size(), before);
    EXPECT_THROW(find_structure("test_bad_default"), InputError);
}

}  // namespace
}  // namespace rcb
