#include "runner/history.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>

#include "core/base/error.h"
#include "sim/simulator.h"
#include "runner/compare.h"
#include "runner/store.h"

namespace rcb {
namespace {

/// The split of runs [lo, hi) at `at` into before [lo, at) and after [at, hi).
struct SplitTest {
    double score = -1;  ///< |shift| / noise; -1 when a side has too few frames to test
    double before = 0, after = 0, noise = 0;
    double p_value = std::numeric_limits<double>::quiet_NaN();
};

std::vector<double> pooled(const std::vector<std::vector<double>>& runs, std::size_t lo, std::size_t hi) {
    std::vector<double> out;
    for (std::size_t i = lo; i < hi; ++i) out.insert(out.end(), runs[i].begin(), runs[i].end());
    return out;
}

SplitTest test_split(const std::vector<std::vector<double>>& runs, std::size_t lo, std::size_t at, std::size_t hi,
                     const StepOptions& o, bool with_p) {
    SplitTest t;
    const std::vector<double> a = pooled(runs, lo, at), b = pooled(runs, at, hi);
    if (a.size() < o.min_frames || b.size() < o.min_frames) return t;
    const Spread sa = spread_of(a), sb = spread_of(b);
    t.before = sa.median;
    t.after = sb.median;
    // The noisier side's MAD (each frame's distance from its own side's median): a side of several
    // runs carries their run-to-run spread, and a side that mixes two levels (a one-run blip beside
    // a quiet run) is too noisy to pass for a level.
    t.noise = std::max(sa.mad, sb.mad);
    const double shift = std::abs(t.after - t.before);
    t.score = t.noise > 0 ? shift / t.noise : (shift > 0 ? std::numeric_limits<double>::infinity() : 0.0);
    if (with_p) t.p_value = mann_whitney_p(a, b);
    return t;
}

double change_of(double before, double after) {
    return before > 0 ? after / before - 1 : (after > 0 ? std::numeric_limits<double>::infinity() : 0.0);
}

bool passes(const SplitTest& t, const StepOptions& o) { return t.score > o.k && t.p_value < o.alpha; }

}  // namespace

std::vector<Step> detect_steps(const std::vector<std::vector<double>>& runs, const StepOptions& o) {
    // Moving windows: every boundary between runs, tested on the w runs either side of it (fewer at
    // the ends), for w from 2 (a level held by two runs) to `window`, keeping the strongest.
    const std::size_t n = runs.size(), widest = std::max<std::size_t>(1, o.window);
    struct Candidate {
        double score;
        std::size_t at, w;
    };
    std::vector<Candidate> candidates;
    for (std::size_t at = 1; at < n; ++at) {
        Candidate best{-1, at, 0};
        for (std::size_t w = std::min<std::size_t>(2, widest); w <= widest; ++w) {
            const SplitTest t = test_split(runs, at > w ? at - w : 0, at, std::min(n, at + w), o, false);
            if (t.score > best.score) best = {t.score, at, w};
        }
        if (best.score > o.k) candidates.push_back(best);
    }
    std::vector<std::size_t> cuts;
    for (const Candidate& c : candidates)
        if (passes(test_split(runs, c.at > c.w ? c.at - c.w : 0, c.at, std::min(n, c.at + c.w), o, true), o))
            cuts.push_back(c.at);
    std::sort(cuts.begin(), cuts.end());
    // A change is seen from the boundaries next to it too. Re-test every cut against its final
    // neighbouring segments and drop the weakest failing cut until all pass: one cut stays per change.
    std::vector<SplitTest> tests;
    for (;;) {
        tests.clear();
        std::size_t weakest = cuts.size();
        for (std::size_t i = 0; i < cuts.size(); ++i) {
            const std::size_t lo = i == 0 ? 0 : cuts[i - 1], hi = i + 1 == cuts.size() ? runs.size() : cuts[i + 1];
            tests.push_back(test_split(runs, lo, cuts[i], hi, o, true));
            if (!passes(tests.back(), o) && (weakest == cuts.size() || tests.back().score < tests[weakest].score))
                weakest = i;
        }
        if (weakest == cuts.size()) break;
        cuts.erase(cuts.begin() + std::ptrdiff_t(weakest));
    }
    std::vector<Step> steps;
    for (std::size_t i = 0; i < cuts.size(); ++i) {
        const SplitTest& t = tests[i];
        Step s;
        s.at = cuts[i];
        s.before = t.before;
        s.after = t.after;
        s.change = change_of(t.before, t.after);
        s.noise = t.noise;
        s.p_value = t.p_value;
        steps.push_back(s);
    }
    return steps;
}

std::string short_commit(const std::string& commit) {
    const std::string suffix = "-dirty";
    const bool dirty =
        commit.size() > suffix.size() && commit.compare(commit.size() - suffix.size(), suffix.size(), suffix) == 0;
    const std::string hash = dirty ? commit.substr(0, commit.size() - suffix.size()) : commit;
    if (hash.size() <= 7 ||
        !std::all_of(hash.begin(), hash.end(), [](unsigned char c) { return std::isxdigit(c) != 0; }))
        return commit;
    return hash.substr(0, 7) + (dirty ? suffix : "");
}

std::vector<HistorySeries> load_history(Database& db, const HistoryQuery& q) {
    if (q.metric != "raycast" && q.metric != "update")
        throw InputError("history: unknown metric " + quoted_excerpt(q.metric) + " (known: raycast, update)");
    if (!q.experiment.empty()) {
        Statement s = db.prepare("SELECT 1 FROM experiment WHERE name = ?");
        s.bind(1, q.experiment);
        if (!s.step()) {
            std::vector<std::string> known;
            Statement k = db.prepare("SELECT name FROM experiment ORDER BY name");
            while (k.step()) known.push_back(k.text(0));
            throw InputError(db.path() + ": no experiment " + quoted_excerpt(q.experiment) +
                             " (known: " + (known.empty() ? std::string("none") : join(known)) + ")");
        }
    }
    std::string up_to_started;
    if (q.up_to_run) {
        Statement s = db.prepare("SELECT started_at FROM run WHERE id = ?");
        s.bind(1, *q.up_to_run);
        if (!s.step()) throw InputError(db.path() + ": no run " + std::to_string(*q.up_to_run));
        up_to_started = s.text(0);
    }
    // The cells first (a few per run), then each cell's frames by the frame table's key.
    Statement cells = db.prepare(
        "SELECT cell.id, run.id, run.git_commit, run.started_at, experiment.name, " + std::string(kSceneLabelSql) +
        ", scene.hash, "
        "config.structure, "
        "config.params, run.binary FROM cell JOIN run ON run.id = cell.run_id JOIN experiment ON experiment.id = "
        "run.experiment_id "
        "JOIN scene ON scene.id = cell.scene_id JOIN config ON config.id = cell.config_id "
        "WHERE (?1 = '' OR experiment.name = ?1) AND (?2 = '' OR scene.name = ?2) AND (?3 = '' OR config.structure = "
        "?3) "
        "AND (?4 = 0 OR run.started_at < ?5 OR (run.started_at = ?5 AND run.id <= ?6)) AND (?7 = '' OR run.binary = "
        "?7) "
        "ORDER BY run.started_at, run.id, cell.id");
    cells.bind_all(q.experiment, q.scene, q.structure, std::int64_t(q.up_to_run ? 1 : 0), up_to_started,
                   q.up_to_run.value_or(0), q.binary);
    // The metric picks one of two fixed column names; every user value is bound.
    Statement frame = db.prepare(std::string("SELECT ") + (q.metric == "raycast" ? "raycast_ns" : "update_ns") +
                                 " FROM frame WHERE cell_id = ? AND warmup = 0 ORDER BY frame");

    // experiment, binary, scene, structure, params: a program's runs and rcbench's are series apart
    using Key = std::tuple<std::string, std::string, std::string, std::string, std::string>;
    std::map<Key, std::size_t> index;
    std::vector<HistorySeries> series;
    std::vector<std::vector<std::vector<double>>> frames;  // per series, per point
    while (cells.step()) {
        std::vector<double> values;
        frame.reset();
        frame.bind(1, cells.int64(0));
        while (frame.step()) values.push_back(frame.real(0));
        if (values.empty()) continue;  // nothing measured outside warm-up
        const Key key{cells.text(4), cells.text(9), cells.text(5), cells.text(7), cells.text(8)};
        auto [it, fresh] = index.try_emplace(key, series.size());
        if (fresh) {
            series.push_back(
                {std::get<0>(key), std::get<2>(key), std::get<3>(key), std::get<4>(key), std::get<1>(key), {}, {}});
            frames.emplace_back();
        }
        HistorySeries& h = series[it->second];
        const std::int64_t run = cells.int64(1);
        if (h.points.empty() || h.points.back().run != run) {  // repetitions of a run pool their frames
            HistoryPoint p;
            p.run = run;
            p.commit = cells.text(2);
            p.started_at = cells.text(3);
            p.scene_hash = cells.text(6);
            h.points.push_back(p);
            frames[it->second].emplace_back();
        }
        std::vector<double>& pool = frames[it->second].back();
        pool.insert(pool.end(), values.begin(), values.end());
    }
    if (series.empty()) {
        std::vector<std::string> filters;
        if (!q.experiment.empty()) filters.push_back("experiment " + quoted_excerpt(q.experiment));
        if (!q.scene.empty()) filters.push_back("scene " + quoted_excerpt(q.scene));
        if (!q.structure.empty()) filters.push_back("structure " + quoted_excerpt(q.structure));
        if (!q.binary.empty()) filters.push_back("binary " + quoted_excerpt(q.binary));
        if (q.up_to_run) filters.push_back("up to run " + std::to_string(*q.up_to_run));
        throw InputError(db.path() + ": no measured cells" +
                         (filters.empty() ? std::string() : " for " + join(filters)));
    }
    for (std::size_t i = 0; i < series.size(); ++i) {
        for (std::size_t j = 0; j < series[i].points.size(); ++j) {
            const Spread sp = spread_of(frames[i][j]);
            series[i].points[j].frames = frames[i][j].size();
            series[i].points[j].median_ns = sp.median;
            series[i].points[j].mad_ns = sp.mad;
        }
        series[i].steps = detect_steps(frames[i], q.steps);
    }
    return series;  // in the order first measured: the experiment's plan order
}

}  // namespace rcb
