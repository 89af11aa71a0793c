#include "tuner/search.h"

#include <nlopt.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

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

SearchResult search_levels(const std::vector<SearchDimension>& dims,
                           const std::function<double(const nlohmann::json&)>& objective, std::size_t budget,
                           std::uint64_t seed) {
    SearchResult result;
    result.space_size = 1;
    for (const SearchDimension& d : dims) result.space_size *= std::max<std::size_t>(1, d.levels.size());
    Budgeted b{&dims, &objective, std::max<std::size_t>(1, budget), {}, &result};

    if (result.space_size <= b.budget) {
        result.algorithm = "enumeration";
        for (const nlohmann::json& p : enumerate_space(dims)) {
            std::vector<int> idx;
            for (const SearchDimension& d : dims)
                idx.push_back(int(std::find(d.levels.begin(), d.levels.end(), p[d.name]) - d.levels.begin()));
            b(idx);
        }
        result.stop_reason = "enumerated";
    } else {
        result.algorithm = "NLopt GN_DIRECT_L_RAND, then LN_SBPLX";
        const unsigned n = unsigned(dims.size());
        std::vector<double> lo(n, 0.0), hi(n);
        for (unsigned d = 0; d < n; ++d) hi[d] = double(dims[d].levels.size() - 1);
        nlopt::srand(seed);
        // Global phase with 70% of the budget.
        const std::size_t global_budget = std::max<std::size_t>(1, b.budget * 7 / 10);
        const std::size_t full_budget = b.budget;
        b.budget = global_budget;
        std::vector<double> x(n);
        for (unsigned d = 0; d < n; ++d) x[d] = hi[d] / 2;
        try {
            nlopt::opt global(nlopt::GN_DIRECT_L_RAND, n);
            global.set_lower_bounds(lo);
            global.set_upper_bounds(hi);
            global.set_min_objective(nlopt_objective, &b);
            global.set_maxeval(int(50 * full_budget));  // calls, memo hits included
            double f = 0;
            const nlopt::result r = global.optimize(x, f);
            result.stop_reason = r == nlopt::MAXEVAL_REACHED ? "budget" : "converged";
        } catch (const nlopt::forced_stop&) {
            result.stop_reason = "budget";
        } catch (const std::exception& e) {
            result.stop_reason = std::string("NLopt failed in the global phase: ") + e.what();
        }
        // Local polish from the best point found so far, with the rest of the budget.
        b.budget = full_budget;
        b.exhausted = false;
        if (!result.evaluations.empty() && b.memo.size() < full_budget) {
            auto best = std::min_element(result.evaluations.begin(), result.evaluations.end(),
                                         [](const Evaluation& a, const Evaluation& c) { return a.cost < c.cost; });
            for (unsigned d = 0; d < n; ++d) {
                const auto& levels = dims[d].levels;
                x[d] = double(std::find(levels.begin(), levels.end(), best->params[dims[d].name]) - levels.begin());
            }
            try {
                nlopt::opt local(nlopt::LN_SBPLX, n);
                local.set_lower_bounds(lo);
                local.set_upper_bounds(hi);
                local.set_min_objective(nlopt_objective, &b);
                local.set_initial_step(std::vector<double>(n, 1.0));
                local.set_xtol_abs(0.49);  // below half a level the point cannot change
                local.set_maxeval(int(50 * full_budget));
                double f = 0;
                local.optimize(x, f);
                result.stop_reason = b.exhausted ? "budget" : "converged";
            } catch (const nlopt::forced_stop&) {
                result.stop_reason = "budget";
            } catch (const std::exception& e) {
                result.stop_reason = std::string("NLopt failed in the local phase: ") + e.what();
            }
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

}  // namespace rcb
