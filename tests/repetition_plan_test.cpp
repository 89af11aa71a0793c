// The one planner (runner/repetition_plan.h): repetition-major order, seeded shuffles that repeat,
// and the orders it gives `rcbench run` and the tuner's measurements (tune, advise) pinned, so a
// change to the planner cannot reorder a run's cells or a tuning's measurements unnoticed.
#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include "runner/experiment.h"
#include "runner/repetition_plan.h"
#include "tests/test_scenes.h"
#include "tests/test_timing.h"
#include "tuner/tuning.h"

namespace rcb {
namespace {

using json = nlohmann::json;

TEST(RepetitionPlan, WithoutASeedEveryRepetitionKeepsTheItemsOrder) {
    const std::vector<PlannedRun> plan = repetition_plan(3, 2, std::nullopt);
    const std::vector<PlannedRun> expected{{0, 0}, {0, 1}, {0, 2}, {1, 0}, {1, 1}, {1, 2}};
    EXPECT_EQ(plan, expected);
    EXPECT_TRUE(repetition_plan(0, 3, std::nullopt).empty());
    EXPECT_TRUE(repetition_plan(4, 0, 7).empty());
}

TEST(RepetitionPlan, ASeedShufflesEachRepetitionItsOwnWayAndTheSameSeedRepeats) {
    const std::size_t items = 40;
    const std::vector<PlannedRun> plan = repetition_plan(items, 3, 12345);
    ASSERT_EQ(plan.size(), 3 * items);
    std::vector<std::vector<std::size_t>> orders(3);
    for (std::size_t i = 0; i < plan.size(); ++i) {
        EXPECT_EQ(plan[i].repetition, i / items);  // repetition-major
        orders[plan[i].repetition].push_back(plan[i].item);
    }
    std::vector<std::size_t> all(items);
    std::iota(all.begin(), all.end(), std::size_t(0));
    for (std::uint32_t r = 0; r < 3; ++r) {
        EXPECT_EQ(orders[r], repetition_order(items, r, 12345));
        std::vector<std::size_t> sorted = orders[r];
        std::sort(sorted.begin(), sorted.end());
        EXPECT_EQ(sorted, all);  // every item once per repetition
        EXPECT_NE(orders[r], all);
    }
    EXPECT_NE(orders[0], orders[1]);  // what runs before an item changes between repetitions
    EXPECT_EQ(plan, repetition_plan(items, 3, 12345));
    EXPECT_NE(plan, repetition_plan(items, 3, 12346));
}

TEST(RepetitionPlan, AnExperimentsPlanIsPinnedCellForCell) {
    // `rcbench run pinned.json --dry-run` printed this plan before the planner was shared; the
    // order is drawn from the file's hash, so the text must stay byte for byte as it is.
    const char* text =
        R"({"name": "pinned", "repetitions": 2, "scenes": [{"preset": "uni-s"}, {"preset": "irreg-s"}], )"
        R"("structures": [{"name": "ug"}, {"name": "bf"}, {"name": "dbvh"}]})";
    const Experiment e = parse_experiment(text, "pinned.json", ".");
    std::vector<std::string> plan;
    for (const Cell& c : e.plan)
        plan.push_back(c.key + " " + e.scenes[c.scene].name + " " + e.configs[c.config].structure + " " +
                       std::to_string(c.repetition));
    const std::vector<std::string> expected{
        "e9e715af71f71b67 uni-s dbvh 0",   "cd6166dacf1bd862 uni-s ug 0",     "e5d90c7777287dd9 irreg-s bf 0",
        "11d1de4d184fae5a uni-s bf 0",     "f034bf162f3281c0 irreg-s dbvh 0", "e85100fcd7c592b1 irreg-s ug 0",
        "14129f1d9cff8431 irreg-s dbvh 1", "57aa622938cb20db uni-s ug 1",     "b99707d09ddc2238 irreg-s bf 1",
        "dfcfa884eeabc934 irreg-s ug 1",   "261f373c26809082 uni-s dbvh 1",   "b4b741b40278a82f uni-s bf 1"};
    EXPECT_EQ(plan, expected);
}

TEST(RepetitionPlan, TheTunersMeasurementsRunRepetitionMajorInTheConfigurationsOrder) {
    // Two scenes told apart by their size, two configurations by their density: every
    // simulation the measurement runs passes through the category's timing, in the order run.
    std::vector<std::pair<double, std::size_t>> order;
    SimulationTiming made_up = test::counted_timing(1.0, 1.0, 1.0);
    TuneCategory c{"u",
                   {test::generated_spec("a", "uniform", 300, 2, 20, {{"plan", 1}}),
                    test::generated_spec("b", "uniform", 400, 2, 20, {{"plan", 2}})},
                   [&](SimulationResult& r) {
                       order.emplace_back(r.params["density"].get<double>(), r.objects);
                       made_up(r);
                   }};
    const std::vector<json> params{{{"density", 2.0}}, {{"density", 8.0}}};
    const std::vector<MeasuredCost> costs = measure_interleaved(c, "ug", params, 0, 2);
    ASSERT_EQ(costs.size(), 2u);
    const std::vector<std::pair<double, std::size_t>> expected{{2.0, 300}, {2.0, 400}, {8.0, 300}, {8.0, 400},
                                                               {2.0, 300}, {2.0, 400}, {8.0, 300}, {8.0, 400}};
    EXPECT_EQ(order, expected);
}

}  // namespace
}  // namespace rcb
