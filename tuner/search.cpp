#include "tuner/search.h"

#include <nlopt.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>

#include "core/base/statistics.h"
#include "core/base/random.h"

namespace rcb {
namespace {

struct Budgeted {
    const std::vector<SearchDimension>* dims;
    const std::function<double(const nlohmann::json&)>* objective;
    std::size_t budget;
    std::map<std::vector<int>, double> memo;
    SearchResult* result;
    bool exhausted = false;

    std::vector<int> snap(const std::vector<double>& x) const {
        std::vector<int> idx(dims->size());
        for (std::size_t d = 0; d < dims->size(); ++d) {
            const int last = int((*dims)[d].levels.size()) - 1;
            idx[d] = std::clamp(int(std::lround(d < x.size() ? x[d] : 0.0)), 0, last);
        }
        return idx;
    }
    nlohmann::json params(const std::vector<int>& idx) const {
        nlohmann::json p = nlohmann::json::object();
        for (std::size_t d = 0; d < dims->size(); ++d) p[(*dims)[d].name] = (*dims)[d].levels[std::size_t(idx[d])];
        return p;
    }
    /// Memoised evaluation; throws nlopt::forced_stop once the budget of distinct points is spent.
    double operator()(const std::vector<int>& idx) {
        auto it = memo.find(idx);
        if (it != memo.end()) return it->second;
        if (memo.size() >= budget) {
            exhausted = true;
            throw nlopt::forced_stop();
        }
        const nlohmann::json p = params(idx);
        double cost = (*objective)(p);
        if (!std::isfinite(cost)) cost = std::numeric_limits<double>::max() / 4;  // failed: avoid it
        memo.emplace(idx, cost);
        result->evaluations.push_back({p, cost});
        return cost;
    }
};

double nlopt_objective(const std::vector<double>& x, std::vector<double>&, void* data) {
    Budgeted& b = *static_cast<Budgeted*>(data);
    return b(b.snap(x));
}

}  // namespace

std::vector<nlohmann::json> enumerate_space(const std::vector<SearchDimension>& dims) {
    std::vector<nlohmann::json> out{nlohmann::json::object()};
    for (const SearchDimension& d : dims) {
        std::vector<nlohmann::json> next;
        for (const nlohmann::json& p : out)
            for (const nlohmann::json& level : d.levels) {
                nlohmann::json q = p;
                q[d.name] = level;
                next.push_back(std::move(q));
            }
        out = std::move(next);
    }
    return out;
}

namespace {

/// What the restarts of one search share about each dimension: the direction that last improved
/// it (0: none yet) and the largest relative change of the cost a step in it has made (∞: never
/// stepped).
struct DimensionMemory {
    std::vector<int> last_dir;
    std::vector<double> effect;
    explicit DimensionMemory(std::size_t n) : last_dir(n, 0), effect(n, std::numeric_limits<double>::infinity()) {}
};

/// Coordinate (compass) search on the level lattice from `idx`, the exploratory move of Hooke &
/// Jeeves restricted to neighbouring levels, a move taken at once. One step per dimension and
/// sweep, so a dimension is revisited after its neighbours moved: grid parameters interact (a
/// coarser top grid wants a different depth), and a line walked to its end in one dimension
/// leaves the budget in a side valley.
///
/// With a budget of a tenth of the space every probe counts, so the search spends them where they
/// are likely to pay. Each sweep takes the dimensions that changed the cost most first, so a
/// parameter that barely matters does not steer the search into a side valley before the ones
/// that do have moved; unprobed ones come before all, in the first sweep in the space's order (the
/// structure's parameter list, main parameters first), later in a seeded order. A dimension is
/// first tried in the direction that last improved it, or, never improved, towards the middle of
/// its levels (a space brackets the optimum it is written for; at the exact middle, a seeded
/// coin). While sweeps improve, a dimension that has moved is tried onward only: the way back was
/// worse when it left. Stops at a point no neighbour improves (a last sweep tries both ways), or
/// when the budget runs out (nlopt::forced_stop propagates).
void pattern_search(Budgeted& b, std::vector<int> idx, Random& rng, DimensionMemory& memory) {
    const std::size_t n = b.dims->size();
    double best = b(idx);
    bool onward_only = true;
    for (bool improved = true; improved;) {
        improved = false;
        std::vector<std::size_t> order(n);
        for (std::size_t d = 0; d < n; ++d) order[d] = d;
        // Until a sweep has probed them, the dimensions keep the space's order (a tuning's space
        // follows the structure's parameter list, which names the main parameters first); then
        // the seeded order breaks ties.
        if (std::any_of(memory.effect.begin(), memory.effect.end(), [](double e) { return !std::isinf(e); }))
            for (std::size_t d = n; d > 1; --d) std::swap(order[d - 1], order[rng.below(d)]);  // Fisher–Yates
        std::stable_sort(order.begin(), order.end(),
                         [&](std::size_t a, std::size_t c) { return memory.effect[a] > memory.effect[c]; });
        for (std::size_t d : order) {
            const int last = int((*b.dims)[d].levels.size()) - 1;
            const int coin = rng.below(2) ? 1 : -1;
            const int towards_middle = 2 * idx[d] > last ? -1 : 2 * idx[d] < last ? 1 : coin;
            const int first_dir = memory.last_dir[d] != 0 ? memory.last_dir[d] : towards_middle;
            for (int dir : {first_dir, -first_dir}) {
                if (dir != first_dir && onward_only && memory.last_dir[d] != 0) break;
                std::vector<int> next = idx;
                next[d] += dir;
                if (next[d] < 0 || next[d] > last) continue;
                const double c = b(next);
                const double change = std::abs(c - best) / std::max(std::abs(best), 1e-300);
                memory.effect[d] = std::isinf(memory.effect[d]) ? change : std::max(memory.effect[d], change);
                if (!(c < best)) continue;
                best = c, idx = next, improved = true, memory.last_dir[d] = dir;
                break;
            }
        }
        // A sweep that found nothing onward tries the ways back too before the search stops.
        if (improved)
            onward_only = true;
        else if (onward_only)
            onward_only = false, improved = true;
    }
}

}  // namespace

SearchResult search_levels(const std::vector<SearchDimension>& dims,
                           const std::function<double(const nlohmann::json&)>& objective, std::size_t budget,
                           std::uint64_t seed, const nlohmann::json& start) {
    SearchResult result;
    result.space_size = 1;
    for (const SearchDimension& d : dims) result.space_size *= std::max<std::size_t>(1, d.levels.size());
    Budgeted b{&dims, &objective, std::max<std::size_t>(1, budget), {}, &result};
    auto index_of = [&](const nlohmann::json& p) {
        std::vector<int> idx;
        for (const SearchDimension& d : dims) {
            auto it = p.is_object() && p.contains(d.name) ? std::find(d.levels.begin(), d.levels.end(), p[d.name])
                                                          : d.levels.end();
            idx.push_back(it == d.levels.end() ? int(d.levels.size() - 1) / 2 : int(it - d.levels.begin()));
        }
        return idx;
    };

    if (result.space_size <= b.budget) {
        result.algorithm = "enumeration";
        for (const nlohmann::json& p : enumerate_space(dims)) b(index_of(p));
        result.stop_reason = "enumerated";
    } else {
        result.algorithm = "level pattern search, restarted from NLopt GN_DIRECT_L_RAND's best";
        Random rng(mix_seed(seed, 11));
        const unsigned n = unsigned(dims.size());
        std::vector<double> lo(n, 0.0), hi(n);
        for (unsigned d = 0; d < n; ++d) hi[d] = double(dims[d].levels.size() - 1);
        const std::size_t full_budget = b.budget;
        DimensionMemory memory(n);
        auto best_index = [&] {
            auto best = std::min_element(result.evaluations.begin(), result.evaluations.end(),
                                         [](const Evaluation& a, const Evaluation& c) { return a.cost < c.cost; });
            return index_of(best->params);
        };
        try {
            // Local first, from the start point (the defaults, usually a good configuration): on
            // the smooth valleys of grid parameters this reaches the optimum in a few steps.
            pattern_search(b, index_of(start), rng, memory);
            // Then, while budget is left, a global look (DIRECT, with half of what is left beyond
            // the points already seen, which it revisits for free) and a local polish from the
            // best point so far; until DIRECT finds nothing new.
            while (b.memo.size() < full_budget) {
                const std::size_t before = b.memo.size();
                b.budget = before + std::max<std::size_t>(1, (full_budget - before) / 2);
                nlopt::srand(seed);
                std::vector<double> x(n);
                for (unsigned d = 0; d < n; ++d) x[d] = hi[d] / 2;
                try {
                    nlopt::opt global(nlopt::GN_DIRECT_L_RAND, n);
                    global.set_lower_bounds(lo);
                    global.set_upper_bounds(hi);
                    global.set_min_objective(nlopt_objective, &b);
                    global.set_maxeval(int(50 * full_budget));  // calls, memo hits included
                    double f = 0;
                    global.optimize(x, f);
                } catch (const nlopt::forced_stop&) {
                } catch (const std::exception& e) {
                    result.stop_reason = std::string("NLopt failed in the global phase: ") + e.what();
                    break;
                }
                b.budget = full_budget;
                b.exhausted = false;
                pattern_search(b, best_index(), rng, memory);
                if (b.memo.size() == before) break;  // nothing new anywhere: converged
            }
            if (result.stop_reason.empty()) result.stop_reason = b.memo.size() >= full_budget ? "budget" : "converged";
        } catch (const nlopt::forced_stop&) {
            result.stop_reason = "budget";
        }
    }
    if (result.evaluations.empty()) return result;
    result.best =
        std::size_t(std::min_element(result.evaluations.begin(), result.evaluations.end(),
                                     [](const Evaluation& a, const Evaluation& c) { return a.cost < c.cost; }) -
                    result.evaluations.begin());
    for (const SearchDimension& d : dims) {
        if (d.levels.size() < 2) continue;
        const nlohmann::json& v = result.evaluations[result.best].params[d.name];
        if (v == d.levels.front() || v == d.levels.back()) result.on_bound.push_back(d.name);
    }
    return result;
}

namespace {

/// Each class's rank key: the median of its members' predictions, NaN as +∞.
std::vector<double> class_predictions(const std::vector<std::size_t>& class_of, const std::vector<double>& predicted,
                                      std::size_t classes) {
    std::vector<std::vector<double>> members(classes);
    for (std::size_t i = 0; i < class_of.size(); ++i)
        members[class_of[i]].push_back(
            i < predicted.size() && !std::isnan(predicted[i]) ? predicted[i] : std::numeric_limits<double>::infinity());
    std::vector<double> out;
    for (const std::vector<double>& m : members)
        out.push_back(m.empty() ? std::numeric_limits<double>::infinity() : median(m));
    return out;
}

}  // namespace

RankedResult rank_then_time(
    const std::vector<std::size_t>& class_of, std::vector<double> predicted, std::size_t budget,
    const std::function<double(std::size_t)>& time,
    const std::function<std::optional<std::vector<double>>(const std::vector<std::size_t>& timed)>& refit) {
    RankedResult out;
    std::size_t classes = 0;
    for (std::size_t c : class_of) classes = std::max(classes, c + 1);
    std::vector<std::size_t> first(classes, SIZE_MAX);  // each class's first member: the one timed
    for (std::size_t i = 0; i < class_of.size(); ++i)
        if (first[class_of[i]] == SIZE_MAX) first[class_of[i]] = i;
    std::vector<bool> done(classes, false);
    std::vector<double> key = class_predictions(class_of, predicted, classes);
    while (out.timed.size() < budget) {
        std::size_t next = SIZE_MAX;  // the best-ranked class not timed yet (ties: the first)
        for (std::size_t c = 0; c < classes; ++c)
            if (!done[c] && first[c] != SIZE_MAX && (next == SIZE_MAX || key[c] < key[next])) next = c;
        if (next == SIZE_MAX) break;
        done[next] = true;
        out.timed.push_back(first[next]);
        out.predicted_when_timed.push_back(key[next]);
        out.costs.push_back(time(first[next]));
        if (!refit || out.timed.size() >= budget) continue;
        if (std::optional<std::vector<double>> p = refit(out.timed)) {
            predicted = std::move(*p);
            key = class_predictions(class_of, predicted, classes);
            ++out.refits;
        }
    }
    // The fastest measured; failed timings (NaN, ∞) only when nothing else was timed.
    for (std::size_t i = 1; i < out.costs.size(); ++i) {
        const double c = out.costs[i], b = out.costs[out.best];
        if (!std::isnan(c) && (std::isnan(b) || c < b)) out.best = i;
    }
    return out;
}

}  // namespace rcb
