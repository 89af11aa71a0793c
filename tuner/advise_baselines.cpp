#include "tuner/advise_baselines.h"

#include <algorithm>
#include <cmath>

#include "core/base/error.h"
#include "core/base/random.h"

namespace rcb {

using json = nlohmann::json;

namespace {

/// The index of `p` among `configurations` (same level per dimension, 4 and 4.0 alike).
std::optional<std::size_t> index_of(const std::vector<SearchDimension>& space, const std::vector<json>& configurations,
                                    const json& p) {
    for (std::size_t i = 0; i < configurations.size(); ++i) {
        bool same = true;
        for (const SearchDimension& d : space)
            same = same && p.contains(d.name) && configurations[i].contains(d.name) &&
                   p[d.name] == configurations[i][d.name];
        if (same) return i;
    }
    return std::nullopt;
}

/// `start` with every level that is missing or not in the space replaced by the middle one.
json on_lattice(const std::vector<SearchDimension>& space, const json& start) {
    json p = json::object();
    for (const SearchDimension& d : space) {
        const bool known = start.is_object() && start.contains(d.name) &&
                           std::find(d.levels.begin(), d.levels.end(), start[d.name]) != d.levels.end();
        p[d.name] = known ? start[d.name] : d.levels[(d.levels.size() - 1) / 2];
    }
    return p;
}

/// The neighbours `stride` levels away from `from`: per dimension in the space's order, up then down.
std::vector<json> neighbours(const std::vector<SearchDimension>& space, const json& from, std::size_t stride) {
    std::vector<json> out;
    for (const SearchDimension& d : space) {
        const auto at = std::find(d.levels.begin(), d.levels.end(), from[d.name]);
        const std::size_t i = std::size_t(at - d.levels.begin());
        if (i + stride < d.levels.size()) out.push_back(from), out.back()[d.name] = d.levels[i + stride];
        if (i >= stride) out.push_back(from), out.back()[d.name] = d.levels[i - stride];
    }
    return out;
}

}  // namespace

std::vector<std::size_t> random_picks(std::size_t space_size, std::size_t count, std::uint64_t seed) {
    count = std::min(count, space_size);
    std::vector<std::size_t> all(space_size);
    for (std::size_t i = 0; i < space_size; ++i) all[i] = i;
    Random random(seed);
    for (std::size_t i = 0; i < count; ++i) std::swap(all[i], all[i + std::size_t(random.below(space_size - i))]);
    all.resize(count);
    return all;
}

std::vector<std::size_t> descent_path(const std::vector<SearchDimension>& space,
                                      const std::vector<json>& configurations, const std::vector<double>& costs,
                                      const json& start, std::size_t budget) {
    std::vector<std::size_t> path;
    if (budget == 0 || configurations.empty()) return path;
    const std::optional<std::size_t> first = index_of(space, configurations, on_lattice(space, start));
    if (!first) throw InputError("descent baseline: its start is not a configuration of the space");
    path.push_back(*first);
    std::size_t current = *first;  // the fastest measured: the descent moves only to a faster one
    // Measures the first unmeasured neighbour `stride` away that is faster; true when it moved.
    auto step = [&](std::size_t stride) {
        for (const json& q : neighbours(space, configurations[current], stride)) {
            if (path.size() == budget) return false;
            const std::optional<std::size_t> k = index_of(space, configurations, q);
            if (!k || std::find(path.begin(), path.end(), *k) != path.end()) continue;
            path.push_back(*k);
            if (costs[*k] < costs[current]) {
                current = *k;
                return true;
            }
        }
        return false;
    };
    while (path.size() < budget && (step(1) || step(2))) {
    }
    return path;
}

std::vector<MethodOutcome> compare_methods(const MethodInputs& in) {
    double best = INFINITY;
    for (const double c : in.costs) best = std::min(best, c);
    std::vector<MethodOutcome> out;
    // A method whose configuration is not in the table (a category level the space lacks) has no row.
    auto add = [&](const std::string& method, std::size_t timed, std::optional<std::size_t> k) {
        if (k) out.push_back({method, timed, in.configurations[*k], in.costs[*k], in.costs[*k] / best - 1});
    };
    // What the baselines see while choosing: their own table when there is one.
    const std::vector<double>& seen = in.choice_costs.empty() ? in.costs : in.choice_costs;
    // The fastest of `picks` as the baseline saw them (ties: the first picked).
    auto fastest = [&](const std::vector<std::size_t>& picks) {
        std::optional<std::size_t> k;
        for (const std::size_t i : picks)
            if (!k || seen[i] < seen[*k]) k = i;
        return k;
    };
    add("advise", in.budget, index_of(in.space, in.configurations, in.advised));
    if (in.advised_on_table)
        add("advise-table", in.advised_on_table->timed,
            index_of(in.space, in.configurations, in.advised_on_table->searched));
    if (in.predicted_best) add("model", 0, index_of(in.space, in.configurations, *in.predicted_best));
    add("category", 0, index_of(in.space, in.configurations, in.category));
    const std::vector<std::size_t> random = random_picks(in.configurations.size(), in.budget, in.seed);
    add("random", random.size(), fastest(random));
    const std::vector<std::size_t> descent = descent_path(in.space, in.configurations, seen, in.category, in.budget);
    add("descent", descent.size(), fastest(descent));
    return out;
}

}  // namespace rcb
