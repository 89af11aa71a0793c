#include "tuner/search_baselines.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <optional>
#include <string>

#include "core/base/statistics.h"
#include "tuner/advise_baselines.h"

namespace rcb {

namespace {

/// P(the lowest of k drawn is the i-th lowest of n), i from 1: C(n − i, k − 1) / C(n, k), k / n for
/// i = 1, then each next one (n − i − k + 1) / (n − i) times the last.
std::vector<double> lowest_of_k_weights(std::size_t n, std::size_t k) {
    std::vector<double> w(n, 0.0);
    double p = double(k) / double(n);
    for (std::size_t i = 1; i <= n - k + 1; ++i) {
        w[i - 1] = p;
        if (i < n) p *= double(n - i - k + 1) / double(n - i);
    }
    return w;
}

double unusable_as_infinite(double c) { return std::isnan(c) ? std::numeric_limits<double>::infinity() : c; }

}  // namespace

double expected_best_of_random(std::vector<double> costs, std::size_t k) {
    return expected_score_of_random(costs, costs, k);
}

double expected_score_of_random(const std::vector<double>& costs, const std::vector<double>& scores, std::size_t k) {
    const std::size_t n = costs.size();
    if (n == 0) return std::numeric_limits<double>::quiet_NaN();
    k = std::clamp<std::size_t>(k, 1, n);
    std::vector<std::size_t> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return unusable_as_infinite(costs[a]) < unusable_as_infinite(costs[b]);
    });
    const std::vector<double> w = lowest_of_k_weights(n, k);
    double expected = 0;
    for (std::size_t i = 0; i < n; ++i)
        if (w[i] > 0) expected += w[i] * unusable_as_infinite(scores[order[i]]);
    return expected;
}

namespace {

/// A class's cost: the median of its members' measurements (one structure measured again).
std::vector<double> class_costs(const std::vector<double>& costs, const std::vector<std::size_t>& class_of,
                                std::size_t classes) {
    std::vector<std::vector<double>> members(classes);
    for (std::size_t i = 0; i < costs.size(); ++i) members[class_of[i]].push_back(unusable_as_infinite(costs[i]));
    std::vector<double> out;
    for (const std::vector<double>& m : members) out.push_back(quantile(m, 0.5));
    return out;
}

}  // namespace

BudgetComparison compare_at_equal_budget(const std::vector<SearchDimension>& dims,
                                         const std::vector<nlohmann::json>& all, const std::vector<double>& costs,
                                         const std::vector<std::size_t>& class_of, const nlohmann::json& start,
                                         double share, std::uint64_t first_seed, std::size_t seeds,
                                         const std::vector<double>& predicted, std::size_t model_timed,
                                         const RankedInputs* ranked, const std::vector<double>& scores) {
    BudgetComparison out;
    out.configurations = all.size();
    out.classes = class_of.empty() ? 0 : *std::max_element(class_of.begin(), class_of.end()) + 1;
    const std::vector<double> class_cost = class_costs(costs, class_of, out.classes);
    const std::vector<double> class_score = class_costs(scores.empty() ? costs : scores, class_of, out.classes);
    // The optimum is the table's best class; its cost is its score, as every choice's is.
    const std::size_t optimum =
        std::size_t(std::min_element(class_cost.begin(), class_cost.end()) - class_cost.begin());
    out.optimum_table = class_cost[optimum];
    out.optimum = class_score[optimum];
    out.budget = std::max<std::size_t>(1, std::size_t(std::ceil(share * double(out.classes))));
    std::map<std::string, std::size_t> class_by_params;  // configuration → its class
    for (std::size_t i = 0; i < all.size(); ++i) class_by_params[all[i].dump()] = class_of[i];
    const auto objective = [&](const nlohmann::json& p) { return class_cost[class_by_params.at(p.dump())]; };
    const auto regret_of_class = [&](std::size_t c) { return class_score[c] / out.optimum - 1; };
    const auto regret = [&](const SearchResult& r) {
        return regret_of_class(class_by_params.at(r.evaluations[r.best].params.dump()));
    };
    for (std::uint64_t seed = first_seed; seed < first_seed + seeds; ++seed)
        out.tuner_regrets.push_back(regret(search_levels(dims, objective, out.budget, seed, start)));
    out.tuner_regret = quantile(out.tuner_regrets, 0.5);
    out.random_regret = expected_score_of_random(class_cost, class_score, out.budget) / out.optimum - 1;
    std::vector<double> config_cost;
    for (std::size_t i = 0; i < all.size(); ++i) config_cost.push_back(class_cost[class_of[i]]);
    std::optional<std::size_t> descended;  // the descent's fastest in the table
    for (std::size_t i : descent_path(dims, all, config_cost, start, out.budget))
        if (!descended || config_cost[i] < config_cost[*descended]) descended = i;
    out.descent_regret = descended ? regret_of_class(class_of[*descended]) : NAN;
    // The model's choice: the lowest prediction (NaN predictions never chosen), at its class's score.
    std::optional<std::size_t> chosen;
    for (std::size_t i = 0; i < predicted.size() && i < all.size(); ++i)
        if (!std::isnan(predicted[i]) && (!chosen || predicted[i] < predicted[*chosen])) chosen = i;
    if (chosen) out.model_regret = regret_of_class(class_of[*chosen]), out.model_timed = model_timed;
    if (ranked && ranked->predicted.size() == all.size()) {
        const auto time = [&](std::size_t i) { return config_cost[i]; };
        const RankedResult r = rank_then_time(class_of, ranked->predicted, out.budget, time, ranked->refit);
        out.ranked_regret = regret_of_class(class_of[r.timed[r.best]]);
        out.ranked_timed = r.timed.size(), out.ranked_replays = ranked->replays, out.ranked_refits = r.refits;
        const RankedResult alone = rank_then_time(class_of, ranked->predicted, out.budget, time);
        out.ranked_unrefitted_regret = regret_of_class(class_of[alone.timed[alone.best]]);
    }
    return out;
}

SuiteSummary summarize_suite(const std::vector<BudgetComparison>& problems) {
    SuiteSummary s;
    s.problems = problems.size();
    if (problems.empty()) return s;
    std::vector<double> tuner, random, descent, shares, model, running, replays;
    std::size_t beats = 0, matches = 0, running_beats = 0, running_matches = 0;
    for (const BudgetComparison& p : problems) {
        tuner.push_back(p.tuner_regret);
        random.push_back(p.random_regret);
        descent.push_back(p.descent_regret);
        shares.push_back(double(p.budget) / double(std::max<std::size_t>(1, p.classes)));
        if (p.tuner_regret < p.random_regret - 1e-9) ++beats;
        if (p.tuner_regret <= p.descent_regret + 1e-9) ++matches;
        if (!std::isnan(p.model_regret)) model.push_back(p.model_regret);
        running.push_back(p.tuner());
        if (p.tuner() < p.random_regret - 1e-9) ++running_beats;
        if (p.tuner() <= p.descent_regret + 1e-9) ++running_matches;
        if (!std::isnan(p.ranked_regret)) replays.push_back(double(p.ranked_replays));
    }
    s.ranked_problems = replays.size();
    if (!replays.empty()) s.median_replays = quantile(replays, 0.5);
    s.running_median = quantile(running, 0.5), s.running_p90 = quantile(running, 0.9);
    s.running_beats_random = double(running_beats) / double(s.problems);
    s.running_matches_descent = double(running_matches) / double(s.problems);
    s.model_problems = model.size();
    if (!model.empty()) s.model_median = quantile(model, 0.5), s.model_p90 = quantile(model, 0.9);
    s.tuner_median = quantile(tuner, 0.5), s.tuner_p90 = quantile(tuner, 0.9);
    s.random_median = quantile(random, 0.5), s.random_p90 = quantile(random, 0.9);
    s.descent_median = quantile(descent, 0.5), s.descent_p90 = quantile(descent, 0.9);
    s.beats_random = double(beats) / double(s.problems);
    s.matches_descent = double(matches) / double(s.problems);
    s.median_budget_share = quantile(shares, 0.5);
    return s;
}

}  // namespace rcb
