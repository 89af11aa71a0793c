// The registry as the one list of structures: a structure registered at run time joins the
// findings, the tuner's default spaces, the report and the differential fuzzer's plan with nothing
// else written for it; lists filtered by origin or family read the registry lines' properties; the
// fuzzer's settings come from the ParamSpecs (dbvh's rebuild mode, lbvh's outlier guard).
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "analysis/charts.h"
#include "analysis/findings.h"
#include "analysis/report.h"
#include "accel/registry.h"
#include "sim/simulator.h"
#include "runner/experiment.h"
#include "runner/run_experiment.h"
#include "testing/differential_settings.h"
#include "tests/test_support.h"
#include "tuner/tuning.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;

/// Registered once per process (the registry is global), on first use.
const StructureInfo& toy() {
    static const StructureInfo& info = register_structure<test::ToyList>(
        "toy", "a list tested in blocks (registry_list_test)", Origin::own, Family::other);
    return info;
}

bool has(const std::vector<std::string>& names, const std::string& name) {
    return std::find(names.begin(), names.end(), name) != names.end();
}

std::vector<std::string> names_where(Origin o) {
    return structure_names([o](const StructureInfo& i) { return i.origin == o; });
}
std::vector<std::string> names_where(Family f) {
    return structure_names([f](const StructureInfo& i) { return i.family == f; });
}

TEST(RegistryList, EveryEntryCarriesItsOriginAndFamily) {
    EXPECT_EQ(names_where(Origin::thesis), (std::vector<std::string>{"bf", "dbvh", "lbvh", "ug", "hg"}));
    EXPECT_EQ(names_where(Origin::peer),
              (std::vector<std::string>{"embree", "bullet_dbvt", "ode_quadtree", "ode_hash", "ode_sap"}));
    EXPECT_TRUE(has(names_where(Origin::own), "wbvh"));
    EXPECT_EQ(names_where(Family::scan), (std::vector<std::string>{"bf"}));
    EXPECT_EQ(names_where(Family::grid), (std::vector<std::string>{"ug", "hg"}));
    EXPECT_EQ(names_where(Family::bvh), (std::vector<std::string>{"dbvh", "lbvh", "wbvh"}));
    EXPECT_EQ(names_where(Family::peer),
              (std::vector<std::string>{"embree", "bullet_dbvt", "ode_quadtree", "ode_hash", "ode_sap"}));
    EXPECT_STREQ(origin_name(find_structure("wbvh").origin), "own");
    EXPECT_STREQ(family_name(find_structure("bullet_dbvt").family), "peer");
    // Unfiltered, the names are the registry in order.
    std::vector<std::string> all;
    for (const StructureInfo& s : structure_registry()) all.push_back(s.name);
    EXPECT_EQ(structure_names(), all);
}

TEST(RegistryList, FindingsCompareEveryStructureButThePeers) {
    toy();
    const std::vector<std::string> compared = findings_structures();
    for (const char* name : {"bf", "ug", "hg", "dbvh", "lbvh", "wbvh", "toy"}) EXPECT_TRUE(has(compared, name)) << name;
    EXPECT_FALSE(has(compared, "embree"));
    EXPECT_FALSE(has(compared, "bullet_dbvt"));
}

TEST(RegistryList, TheTunersDefaultSpaceHasTheToy) {
    toy();
    // The default structure list is every registered one with a tunable parameter; a tuning file
    // naming none takes wbvh's whole space too, over the plan limit, so the toy is named here.
    const TuneSpec t = parse_tune_spec(
        R"({"mode": "measured", "structures": ["toy"],
            "categories": [{"name": "small", "scenes": [{"generator": "irregular", "objects": 100}]}]})",
        "t.json", ".");
    ASSERT_TRUE(t.space.count("toy"));
    const auto dims = default_space("toy");
    EXPECT_EQ(t.space.at("toy").size(), dims.size());
    EXPECT_TRUE(std::any_of(dims.begin(), dims.end(), [](const SearchDimension& d) { return d.name == "block"; }));
    EXPECT_FALSE(std::any_of(dims.begin(), dims.end(), [](const SearchDimension& d) { return d.name == "backwards"; }));
}

/// The fuzzer's setting of `structure` that sets `key` to `value` alone, if any.
bool has_setting(const std::string& structure, const std::string& key, const nlohmann::json& value) {
    for (const nlohmann::json& s : fuzz::differential_settings(find_structure(structure)))
        if (s == nlohmann::json{{key, value}}) return true;
    return false;
}

TEST(RegistryList, TheFuzzersSettingsComeFromTheParamSpecs) {
    toy();
    const auto plan = fuzz::differential_plan();
    ASSERT_EQ(plan.size(), structure_registry().size());
    EXPECT_EQ(plan.back().first, &toy());
    EXPECT_TRUE(has_setting("toy", "backwards", true));
    EXPECT_TRUE(has_setting("dbvh", "mode", "rebuild"));
    EXPECT_TRUE(has_setting("lbvh", "outlier_guard", false));
    EXPECT_TRUE(has_setting("hg", "entries_guard", false));
    EXPECT_TRUE(has_setting("bf", "query", "candidates"));
    EXPECT_TRUE(has_setting("hg", "max_capacity", 1));
    EXPECT_TRUE(has_setting("wbvh", "leaf_size", 1));
    // Every setting is one its structure accepts, and the first is the defaults.
    for (const auto& [info, settings] : plan) {
        ASSERT_FALSE(settings.empty());
        EXPECT_EQ(settings.front(), nlohmann::json::object()) << info->name;
        for (const nlohmann::json& s : settings) EXPECT_NO_THROW(info->complete(s, "fuzz")) << info->name << s.dump();
    }
    // The toy's one number at its lower end, alone and with its bool flipped.
    const auto toy_settings = fuzz::differential_settings(toy());
    EXPECT_NE(std::find(toy_settings.begin(), toy_settings.end(), nlohmann::json{{"block", 1}}), toy_settings.end());
    EXPECT_NE(std::find(toy_settings.begin(), toy_settings.end(), nlohmann::json{{"block", 1}, {"backwards", true}}),
              toy_settings.end());
}

TEST(RegistryList, EveryFuzzerSettingMatchesTheGroundTruth) {
    toy();
    const Experiment e = parse_experiment(
        R"({"frames": 3, "rays_per_frame": 60, "scenes": [{"generator": "irregular", "objects": 150, "sphere_share": 0.2}],
            "structures": [{"name": "bf"}]})",
        "fuzz-settings.json", ".");
    const Recording r = load_scene(e.scenes.at(0));
    SimulationOptions o;
    o.verify = o.count = o.check = true;
    for (const auto& [info, settings] : fuzz::differential_plan())
        for (const nlohmann::json& s : settings)
            EXPECT_EQ(simulate(r, *info, s, o).mismatches(), 0u) << info->name << " " << s.dump();
}

std::string read(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::ostringstream s;
    s << in.rdbuf();
    return s.str();
}

TEST(RegistryList, TheReportAndItsFindingsShowTheToy) {
    ASSERT_TRUE(gnuplot_available()) << "gnuplot is part of rcbench's dependencies";
    toy();
    const fs::path dir = fs::temp_directory_path() / ("rcb_registry_list_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const Experiment e = parse_experiment(
        R"({"name": "registry-list", "frames": 3, "rays_per_frame": 50,
            "scenes": [{"generator": "irregular", "objects": 60}, {"generator": "irregular", "objects": 240}],
            "structures": [{"name": "bf"}, {"name": "toy"}, {"name": "toy", "params": {"block": 16}}]})",
        "registry-list.json", ".");
    RunOptions options;
    options.db = (dir / "r.db").string();
    options.new_run = true;
    const std::int64_t run = run_experiment(e, "registry-list.json", options).run;

    Database db(options.db, true);
    // The small-scenes finding compares bf with the best of the others: the toy is the only other.
    const std::vector<Finding> findings = evaluate_findings(db, run);
    bool in_findings = false;
    for (const Finding& f : findings)
        for (const std::string& line : f.evidence) in_findings = in_findings || line.find("toy") != std::string::npos;
    EXPECT_TRUE(in_findings);
    EXPECT_NE(findings_markdown({{&db, run}}).find(", toy;"), std::string::npos);

    write_report(db, run, (dir / "report.html").string());
    const std::string page = read(dir / "report.html");
    EXPECT_NE(page.find("<tr><td>toy</td>"), std::string::npos);           // Tables 6.1 and 6.2
    EXPECT_NE(page.find("<tr><td>toy block=16</td>"), std::string::npos);  // a configuration off its defaults
    EXPECT_NE(page.find("the time of toy, the best"), std::string::npos);  // the findings' evidence
    fs::remove_all(dir);
}

}  // namespace
}  // namespace rcb
