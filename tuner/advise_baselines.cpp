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
                                      const json& start, std::size_t budget, const std::vector<std::size_t>& class_of,
                                      std::size_t replays, std::size_t* replayed) {
    std::vector<std::size_t> path;
    std::size_t replays_used = 0;
    if (replayed) *replayed = 0;
    if (budget == 0 || configurations.empty()) return path;
    const std::optional<std::size_t> first = index_of(space, configurations, on_lattice(space, start));
    if (!first) throw InputError("descent baseline: its start is not a configuration of the space");
    std::vector<std::size_t> seen;  // configurations timed or replayed: none is looked at twice
    // Replays while they remain: the start's too, so that its twins are known as measured.
    auto replay = [&]() {
        if (class_of.empty() || replays_used == replays) return false;
        ++replays_used;
        return true;
    };
    std::vector<std::size_t> known_classes;  // of the timed configurations that were replayed
    if (replay()) known_classes.push_back(class_of[*first]);
    path.push_back(*first);
    seen.push_back(*first);
    std::size_t current = *first;  // the fastest measured: the descent moves only to a faster one
    // Measures the first unseen neighbour `stride` away that is faster; true when it moved.
    auto step = [&](std::size_t stride) {
        for (const json& q : neighbours(space, configurations[current], stride)) {
            if (path.size() == budget) return false;
            const std::optional<std::size_t> k = index_of(space, configurations, q);
            if (!k || std::find(seen.begin(), seen.end(), *k) != seen.end()) continue;
            seen.push_back(*k);
            if (replay()) {
                const std::size_t c = class_of[*k];
                // A structure measured already: its cost is known, nothing to time.
                if (std::find(known_classes.begin(), known_classes.end(), c) != known_classes.end()) continue;
                known_classes.push_back(c);
            }
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
    if (replayed) *replayed = replays_used;
    return path;
}

std::vector<std::size_t> random_timed(std::size_t space_size, std::size_t budget, std::size_t replays,
                                      const std::vector<std::size_t>& class_of, std::uint64_t seed) {
    if (replays == 0 || class_of.empty()) return random_picks(space_size, budget, seed);
    std::vector<std::size_t> timed, classes;
    for (const std::size_t i : random_picks(space_size, replays, seed)) {
        if (timed.size() == budget) break;
        if (std::find(classes.begin(), classes.end(), class_of[i]) != classes.end()) continue;
        classes.push_back(class_of[i]);
        timed.push_back(i);
    }
    return timed;
}

std::vector<MethodOutcome> choose_methods(const MethodInputs& in, std::size_t& optimum) {
    const std::vector<double>& table = in.table;
    optimum = 0;
    for (std::size_t i = 1; i < table.size(); ++i)
        if (table[i] < table[optimum]) optimum = i;
    std::vector<MethodOutcome> out;
    // A method whose configuration is not in the table (a category level the space lacks) has no row.
    auto add = [&](const std::string& method, std::size_t timed, std::size_t replays, std::optional<std::size_t> k) {
        if (k) out.push_back({method, timed, replays, *k, in.configurations[*k], table[*k], 0, 0});
    };
    // The fastest of `picks` in the table (ties: the first picked).
    auto fastest = [&](const std::vector<std::size_t>& picks) {
        std::optional<std::size_t> k;
        for (const std::size_t i : picks)
            if (!k || table[i] < table[*k]) k = i;
        return k;
    };
    add("advise", in.budget, in.replays, index_of(in.space, in.configurations, in.advised));
    if (in.advised_on_table)
        add("advise-table", in.advised_on_table->timed, in.advised_on_table->replays,
            index_of(in.space, in.configurations, in.advised_on_table->searched));
    if (in.predicted_best) add("model", 0, in.replays, index_of(in.space, in.configurations, *in.predicted_best));
    add("category", 0, 0, index_of(in.space, in.configurations, in.category));
    const std::size_t n = in.configurations.size();
    const std::size_t random_replays = in.class_of.empty() ? 0 : std::min(in.replays, n);
    const std::vector<std::size_t> random = random_timed(n, in.budget, random_replays, in.class_of, in.seed);
    add("random", random.size(), random_replays, fastest(random));
    std::size_t descent_replays = 0;
    const std::vector<std::size_t> descent = descent_path(in.space, in.configurations, table, in.category, in.budget,
                                                          in.class_of, in.replays, &descent_replays);
    add("descent", descent.size(), descent_replays, fastest(descent));
    return out;
}

std::vector<std::size_t> to_rescore(const std::vector<MethodOutcome>& choices, std::size_t optimum) {
    std::vector<std::size_t> out{optimum};
    for (const MethodOutcome& m : choices)
        if (std::find(out.begin(), out.end(), m.index) == out.end()) out.push_back(m.index);
    return out;
}

void score_methods(std::vector<MethodOutcome>& choices, std::size_t optimum, const std::vector<double>& rescored) {
    for (MethodOutcome& m : choices) {
        m.ms = rescored[m.index];
        m.regret = m.ms / rescored[optimum] - 1;
    }
}

MethodComparison compare_methods(const MethodInputs& in,
                                 const std::function<std::vector<double>(const std::vector<std::size_t>&)>& rescore) {
    MethodComparison out;
    out.methods = choose_methods(in, out.optimum);
    const std::vector<std::size_t> indices = to_rescore(out.methods, out.optimum);
    const std::vector<double> measured = rescore(indices);
    std::vector<double> rescored(in.configurations.size(), NAN);
    for (std::size_t i = 0; i < indices.size(); ++i) rescored[indices[i]] = measured.at(i);
    score_methods(out.methods, out.optimum, rescored);
    out.optimum_table_ms = in.table.empty() ? NAN : in.table[out.optimum];
    out.optimum_ms = rescored.empty() ? NAN : rescored[out.optimum];
    return out;
}

}  // namespace rcb
