#include "runner/compare.h"

#include <algorithm>
#include <charconv>
#include <cctype>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>

#include "core/base/error.h"
#include "sim/simulator.h"
#include "runner/store.h"

namespace rcb {

double mann_whitney_p(const std::vector<double>& a, const std::vector<double>& b) {
    const double n1 = double(a.size()), n2 = double(b.size());
    if (a.empty() || b.empty()) return std::numeric_limits<double>::quiet_NaN();
    // Rank the pooled sample, averaging ranks over ties.
    std::vector<std::pair<double, int>> pooled;
    for (double x : a) pooled.emplace_back(x, 0);
    for (double x : b) pooled.emplace_back(x, 1);
    std::sort(pooled.begin(), pooled.end());
    double rank_sum_a = 0, tie_term = 0;
    for (std::size_t i = 0; i < pooled.size();) {
        std::size_t j = i;
        while (j < pooled.size() && pooled[j].first == pooled[i].first) ++j;
        const double t = double(j - i);
        const double rank = (double(i + 1) + double(j)) / 2.0;
        for (std::size_t k = i; k < j; ++k)
            if (pooled[k].second == 0) rank_sum_a += rank;
        tie_term += t * t * t - t;
        i = j;
    }
    const double u = rank_sum_a - n1 * (n1 + 1) / 2;
    const double n = n1 + n2;
    const double mean = n1 * n2 / 2;
    const double variance = n1 * n2 / 12 * ((n + 1) - tie_term / (n * (n - 1)));
    if (variance <= 0) return 1.0;  // every value equal
    const double z = (std::abs(u - mean) - 0.5) / std::sqrt(variance);
    return std::min(1.0, std::erfc(std::max(0.0, z) / std::sqrt(2.0)));
}

std::vector<std::int64_t> select_runs(Database& db, const std::string& selector) {
    std::vector<std::int64_t> runs;
    // A run id (decimal digits that fit), or a commit prefix: `git describe` output, at most 64
    // characters of letters, digits, '-', '.' and '_' (so no LIKE wildcards either).
    std::int64_t id = 0;
    const auto [end, ec] = std::from_chars(selector.data(), selector.data() + selector.size(), id);
    const bool numeric = !selector.empty() && ec == std::errc() && end == selector.data() + selector.size() && id >= 0;
    const bool commit = !selector.empty() && selector.size() <= 64 &&
                        std::all_of(selector.begin(), selector.end(), [](unsigned char c) {
                            return std::isalnum(c) || c == '-' || c == '.' || c == '_';
                        });
    if (!numeric && !commit) throw InputError(quoted_excerpt(selector) + ": not a run id or a git commit prefix");
    Statement s = db.prepare(numeric ? "SELECT id FROM run WHERE id = ?"
                                     : "SELECT id FROM run WHERE git_commit LIKE ? || '%' ORDER BY id");
    if (numeric)
        s.bind(1, id);
    else
        s.bind(1, selector);
    while (s.step()) runs.push_back(s.int64(0));
    if (runs.empty()) throw InputError("no run matches '" + selector + "' (give a run id or a git commit prefix)");
    return runs;
}

std::vector<std::string> run_binaries(Database& db, const std::string& selector) {
    std::vector<std::string> out;
    Statement s = db.prepare("SELECT binary FROM run WHERE id = ?");
    for (const std::int64_t run : select_runs(db, selector)) {
        s.reset();
        s.bind(1, run);
        if (s.step() && std::find(out.begin(), out.end(), s.text(0)) == out.end()) out.push_back(s.text(0));
    }
    return out;
}

namespace {

using Key = std::tuple<std::string, std::string, std::string>;  // scene hash, structure, params

struct Samples {
    std::string scene_name;
    std::vector<double> raycast, update;
    std::size_t slow_cells = 0;
};

std::map<Key, Samples> frames_of(Database& db, const std::vector<std::int64_t>& runs) {
    std::map<Key, Samples> out;
    const std::string ids = join(runs, ",", [](std::int64_t r) { return std::to_string(r); });
    Statement s = db.prepare("SELECT scene.hash, " + std::string(kSceneLabelSql) +
                             ", config.structure, config.params, frame.raycast_ns, frame.update_ns "
                             "FROM frame JOIN cell ON cell.id = frame.cell_id JOIN scene ON scene.id = cell.scene_id "
                             "JOIN config ON config.id = cell.config_id WHERE frame.warmup = 0 AND cell.run_id IN (" +
                             ids + ")");
    while (s.step()) {
        Samples& x = out[{s.text(0), s.text(2), s.text(3)}];
        x.scene_name = s.text(1);
        x.raycast.push_back(s.real(4));
        x.update.push_back(s.real(5));
    }
    Statement slow = db.prepare(
        "SELECT scene.hash, config.structure, config.params, count(*) FROM cell "
        "JOIN cell_state ON cell_state.cell_id = cell.id JOIN scene ON scene.id = cell.scene_id "
        "JOIN config ON config.id = cell.config_id WHERE cell_state.slow = 1 AND cell.run_id IN (" +
        ids + ") GROUP BY scene.hash, config.structure, config.params");
    while (slow.step()) {
        auto it = out.find({slow.text(0), slow.text(1), slow.text(2)});
        if (it != out.end()) it->second.slow_cells = std::size_t(slow.int64(3));
    }
    return out;
}

}  // namespace

std::vector<Comparison> compare_runs(Database& db, const std::string& baseline, const std::string& candidate,
                                     const std::string& metric, double alpha) {
    const auto named = [&](const char* option, const std::string& selector) {
        try {
            return select_runs(db, selector);
        } catch (const InputError& e) {
            throw InputError(std::string(option) + " " + e.what());
        }
    };
    const auto base = frames_of(db, named("--baseline", baseline));
    const auto cand = frames_of(db, named("--candidate", candidate));
    std::vector<Comparison> out;
    for (const auto& [key, b] : base) {
        auto it = cand.find(key);
        if (it == cand.end()) continue;
        for (const std::string m : {"raycast", "update"}) {
            if (metric != "both" && metric != m) continue;
            const std::vector<double>& x = m == "raycast" ? b.raycast : b.update;
            const std::vector<double>& y = m == "raycast" ? it->second.raycast : it->second.update;
            Comparison c;
            c.scene = b.scene_name;
            c.structure = std::get<1>(key);
            c.params = std::get<2>(key);
            c.metric = m;
            c.baseline_n = x.size();
            c.candidate_n = y.size();
            c.baseline_median = spread_of(x).median;
            c.candidate_median = spread_of(y).median;
            c.ratio = c.baseline_median > 0 ? c.candidate_median / c.baseline_median
                                            : std::numeric_limits<double>::quiet_NaN();
            c.p_value = mann_whitney_p(x, y);
            c.baseline_slow = b.slow_cells;
            c.candidate_slow = it->second.slow_cells;
            if (x.size() < 5 || y.size() < 5)
                c.verdict = "too few frames";
            else if (c.p_value < alpha)
                c.verdict = c.ratio > 1 ? "slower" : "faster";
            else
                c.verdict = "same";
            out.push_back(c);
        }
    }
    if (out.empty())
        throw InputError("the runs '" + baseline + "' and '" + candidate + "' share no scene and configuration");
    return out;
}

}  // namespace rcb
