#include "analysis/findings.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <tuple>

#include <nlohmann/json.hpp>

#include "core/base/statistics.h"
#include "analysis/cost_model.h"
#include "accel/registry.h"
#include "core/base/number_text.h"
#include "sim/simulator.h"
#include "runner/results_reader.h"

namespace rcb {

namespace {

/// The thesis' scenes below this size showed "little or no speed-up" (§6.3); claims about which
/// structure wins are read on the larger ones.
constexpr double kLargeScene = 1000;
/// Within this of the fastest counts as "as good as the best" (a partly-confirmed verdict).
constexpr double kNearBest = 0.10;

/// The compared structures of the given families, family by family in that order (grids before
/// BVHs, as the thesis' tables list them), each family in registry order.
std::vector<std::string> compared_of(std::initializer_list<Family> families) {
    const std::vector<std::string> compared = findings_structures();
    std::vector<std::string> out;
    for (Family f : families)
        for (const std::string& name : compared)
            if (find_structure(name).family == f) out.push_back(name);
    return out;
}

/// "a, b and c".
std::string listed(const std::vector<std::string>& names, const std::string& suffix = "") {
    std::string out;
    for (std::size_t i = 0; i < names.size(); ++i)
        out += (i == 0 ? "" : i + 1 == names.size() ? " and " : ", ") + names[i] + suffix;
    return out;
}

bool contains(const std::vector<std::string>& names, const std::string& name) {
    return std::find(names.begin(), names.end(), name) != names.end();
}

/// One configuration on one scene: per run its times over the repetitions (analysis/repetitions.h)
/// and its counters' medians over them; over several runs the median of those, with the range over
/// runs of the times (lo, hi).
struct Config {
    std::string scene, category, structure, ray_mix;
    nlohmann::json params;
    double objects = 0;
    double update_ms = 0, ray_ms = 0, bytes_per_object = 0;
    double n_t = 0, n_rb = 0, n_tp = 0;  ///< per ray, over frames that are not warm-up
    double frame = 0;                    ///< update + ray cast (over runs: the median of the runs' sums)
    double frame_lo = 0, frame_hi = 0, ray_lo = 0, ray_hi = 0, update_lo = 0, update_hi = 0;
    std::size_t runs = 1;  ///< runs that measured it
    double frame_ms() const { return frame; }
};

/// The thesis cast dense rays (from the centre towards the densest region) for Tables 6.3 and 6.4.
bool dense_rays(const Config& c) { return c.ray_mix.find("dense") != std::string::npos; }

/// Smallest scene first, then by name; each scene's structures as findings_structures lists them,
/// each structure's configurations by their parameters' values (numbers as numbers): an order of
/// the experiment's contents, not of the shuffled order the cells were measured in.
void sort_for_listing(std::vector<Config>& configs) {
    const std::vector<std::string> compared = findings_structures();
    auto rank = [&](const Config& c) {
        const auto at = std::find(compared.begin(), compared.end(), c.structure) - compared.begin();
        return std::tuple<double, const std::string&, std::ptrdiff_t, const nlohmann::json&>(c.objects, c.scene, at,
                                                                                             c.params);
    };
    std::stable_sort(configs.begin(), configs.end(),
                     [&](const Config& a, const Config& b) { return rank(a) < rank(b); });
}

std::vector<Config> load_configs(Database& db, std::int64_t run, OverRepetitions how) {
    const auto figures = cell_figures(db, run, how);
    struct Acc {
        Config c;
        std::vector<double> update, ray, bytes, n_t, n_rb, n_tp;
    };
    std::map<std::tuple<std::string, std::string, std::string>, Acc> acc;
    std::vector<std::tuple<std::string, std::string, std::string>> order;
    const std::vector<std::string> compared = findings_structures();
    for (const CellCountsRow& r : read_cell_counts(db, run)) {
        if (!contains(compared, r.structure)) continue;
        const auto key = std::make_tuple(r.scene, r.structure, r.params);
        auto [it, fresh] = acc.try_emplace(key);
        if (fresh) order.push_back(key);
        Acc& a = it->second;
        a.c.scene = r.scene;
        a.c.category = scene_category(r.spec);
        a.c.ray_mix = scene_ray_mix(r.spec);
        a.c.objects = double(r.objects);
        a.c.structure = r.structure;
        a.c.params = nlohmann::json::parse(r.params, nullptr, false);
        const CellFigure& figure = figures.at({r.scene_id, r.config_id});
        a.update.push_back(figure.update_ns * 1e-6);
        a.ray.push_back(figure.raycast_ns * 1e-6);
        a.bytes.push_back(a.c.objects > 0 ? double(r.memory_bytes) / a.c.objects : NAN);
        a.n_t.push_back(r.n_t);
        a.n_rb.push_back(r.n_rb);
        a.n_tp.push_back(r.n_tp);
    }
    std::vector<Config> out;
    for (const auto& key : order) {
        Acc& a = acc.at(key);
        a.c.update_ms = median(a.update), a.c.ray_ms = median(a.ray), a.c.bytes_per_object = median(a.bytes);
        a.c.n_t = median(a.n_t), a.c.n_rb = median(a.n_rb), a.c.n_tp = median(a.n_tp);
        a.c.frame = a.c.update_ms + a.c.ray_ms;  // the ranges over runs: merge_runs, read from two runs on
        out.push_back(a.c);
    }
    sort_for_listing(out);
    return out;
}

/// A figure over runs: the median of the runs' values and their range.
struct OverRuns {
    double median = 0, lo = 0, hi = 0;
    std::size_t runs = 0;
};
OverRuns over_runs(const std::vector<double>& v) {
    const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
    return {median(v), *lo, *hi, v.size()};
}

/// Each configuration over the runs (one Config per scene, structure and parameters, in the order
/// of sort_for_listing): the median of its per-run figures and the range of its times. A
/// configuration that a run lacks is summarised over the runs that have it (Config::runs says how
/// many).
std::vector<Config> merge_runs(const std::vector<std::vector<Config>>& runs) {
    if (runs.size() == 1) return runs.front();
    using Key = std::tuple<std::string, std::string, std::string>;
    std::map<Key, std::vector<const Config*>> by;
    for (const std::vector<Config>& run : runs)
        for (const Config& c : run) by[Key{c.scene, c.structure, c.params.dump()}].push_back(&c);
    std::vector<Config> out;
    for (const auto& entry : by) {
        const std::vector<const Config*>& all = entry.second;  // clang 14 cannot capture a structured binding
        auto of = [&](double Config::*field) {
            std::vector<double> v;
            for (const Config* c : all) v.push_back(c->*field);
            return over_runs(v);
        };
        Config m = *all.front();
        const OverRuns frame = of(&Config::frame), ray = of(&Config::ray_ms), update = of(&Config::update_ms);
        m.frame = frame.median, m.frame_lo = frame.lo, m.frame_hi = frame.hi;
        m.ray_ms = ray.median, m.ray_lo = ray.lo, m.ray_hi = ray.hi;
        m.update_ms = update.median, m.update_lo = update.lo, m.update_hi = update.hi;
        m.bytes_per_object = of(&Config::bytes_per_object).median;
        m.n_t = of(&Config::n_t).median, m.n_rb = of(&Config::n_rb).median, m.n_tp = of(&Config::n_tp).median;
        m.runs = all.size();
        out.push_back(std::move(m));
    }
    sort_for_listing(out);  // a configuration only a later run has goes where its scene belongs, too
    return out;
}

/// Per scene: each own structure at its fastest configuration (update + ray cast per frame).
struct Scene {
    std::string name, category;
    double objects = 0;
    std::map<std::string, Config> best;  ///< by structure
    /// Structures other than the scans (bf: the baseline), fastest first.
    std::vector<const Config*> ranking() const {
        std::vector<const Config*> r;
        for (const auto& [name, c] : best)
            if (find_structure(name).family != Family::scan) r.push_back(&c);
        std::sort(r.begin(), r.end(), [](const Config* a, const Config* b) { return a->frame_ms() < b->frame_ms(); });
        return r;
    }
    /// The scan (bf), the baseline speed-ups are measured against; nullptr when the scene has none.
    const Config* baseline() const {
        for (const auto& [name, c] : best)
            if (find_structure(name).family == Family::scan) return &c;
        return nullptr;
    }
};

std::vector<Scene> scenes_of(const std::vector<Config>& configs) {
    std::vector<Scene> out;
    for (const Config& c : configs) {
        auto it = std::find_if(out.begin(), out.end(), [&](const Scene& s) { return s.name == c.scene; });
        if (it == out.end()) {
            out.push_back(Scene{c.scene, c.category, c.objects, {}});
            it = out.end() - 1;
        }
        auto [b, fresh] = it->best.try_emplace(c.structure, c);
        if (!fresh && c.frame_ms() < b->second.frame_ms()) b->second = c;
    }
    return out;
}

/// A claim not yet decided: the verdict stays "untested" unless the run has what it needs.
Finding claim(std::string text, std::string source) {
    return {std::move(text), std::move(source), Finding::Verdict::untested, "", {}, {}};
}

/// Confirmed when it holds everywhere it was tested, partly when somewhere, refuted when nowhere.
Finding::Verdict verdict(bool everywhere, bool somewhere) {
    return everywhere ? Finding::Verdict::confirmed : somewhere ? Finding::Verdict::partly : Finding::Verdict::refuted;
}

/// Why a claim about large scenes stayed untested.
std::string no_large_scene(const std::string& which, const std::string& with) {
    return "The run has no " + which + "scene of " + fixed(kLargeScene, 0) + " objects or more with " + with + ".";
}

std::string ms(double v) { return format_ms(v) + " ms"; }
/// A time over runs: "0.449 ms [0.440–0.461]", the range over the runs that measured it; one run:
/// "0.449 ms".
std::string ms(double v, double lo, double hi, std::size_t runs) {
    if (runs < 2) return ms(v);
    const int digits = ms_decimals(v);
    return ms(v) + " [" + fixed(lo, digits) + "–" + fixed(hi, digits) + "]";
}
std::string frame_of(const Config& c) { return ms(c.frame_ms(), c.frame_lo, c.frame_hi, c.runs); }
std::string rays_of(const Config& c) { return ms(c.ray_ms, c.ray_lo, c.ray_hi, c.runs); }
std::string update_of(const Config& c) { return ms(c.update_ms, c.update_lo, c.update_hi, c.runs); }
std::string ratio(double v) { return fixed(v, v < 10 ? 2 : 1) + "x"; }
std::string pct(double v) { return fixed(100 * v, 0) + "%"; }
std::string counters(const Config& c) {
    return "N_T " + fixed(c.n_t, 1) + ", N_RB " + fixed(c.n_rb, 1) + ", N_TP " + fixed(c.n_tp, 1) + " per ray";
}

/// "ug 0.95 ms (update 0.10 + rays 0.85; N_T …), hg 1.20 ms (1.26x), …" for one scene's ranking.
std::string ranking_line(const Scene& s) {
    const std::vector<const Config*> r = s.ranking();
    std::string line = s.name + " (" + fixed(s.objects, 0) + " objects): ";
    for (std::size_t i = 0; i < r.size(); ++i) {
        const Config& c = *r[i];
        line += (i ? "; " : "") + c.structure + " " + frame_of(c) +
                (i ? " (" + ratio(c.frame_ms() / r[0]->frame_ms()) + ")" : "") + " (update " + ms(c.update_ms) +
                ", rays " + ms(c.ray_ms) + "; " + counters(c) + ")";
    }
    return line;
}

/// "The winner on every scene" claims: `who` fastest per frame on the large scenes of `category`.
Finding best_on(const std::vector<Scene>& scenes, const std::string& category, const std::string& who, std::string text,
                std::string source) {
    Finding f = claim(std::move(text), std::move(source));
    int tested = 0, first = 0, near = 0;
    std::vector<std::string> winners;
    for (const Scene& s : scenes) {
        if (s.category != category || s.objects < kLargeScene || !s.best.count(who)) continue;
        const std::vector<const Config*> r = s.ranking();
        if (r.size() < 2) continue;
        ++tested;
        const double gap = s.best.at(who).frame_ms() / r[0]->frame_ms() - 1;
        first += r[0]->structure == who;
        near += gap <= kNearBest;
        if (r[0]->structure != who) winners.push_back(s.name + ": " + r[0]->structure + ", " + who + " +" + pct(gap));
        f.evidence.push_back(ranking_line(s));
    }
    if (tested == 0) {
        f.summary = no_large_scene(category + " ", who + " and another structure");
        return f;
    }
    f.verdict = verdict(first == tested, near == tested || first > 0);
    f.summary = who + " is the fastest per frame on " + std::to_string(first) + " of " + std::to_string(tested) + " " +
                category + " scenes" + (winners.empty() ? "." : "; elsewhere: " + join(winners, "; ") + ".");
    return f;
}

Finding lbvh_trade(const std::vector<Scene>& scenes) {
    Finding f = claim(
        "LBVH casts fast but its rebuild every frame makes its updates the slowest, which lowers its overall "
        "standing.",
        "§6.3, Table 6.2; §7.1");
    int tested = 0, fast_rays = 0, slow_updates = 0;
    std::vector<std::string> other_names = compared_of({Family::grid, Family::bvh});
    std::erase(other_names, "lbvh");
    for (const Scene& s : scenes) {
        if (s.objects < kLargeScene || !s.best.count("lbvh")) continue;
        std::vector<const Config*> others;
        for (const std::string& o : other_names)
            if (s.best.count(o)) others.push_back(&s.best.at(o));
        if (others.empty()) continue;
        ++tested;
        const Config& l = s.best.at("lbvh");
        int faster_rays = 0;
        double max_update = 0;
        for (const Config* o : others)
            faster_rays += l.ray_ms <= o->ray_ms, max_update = std::max(max_update, o->update_ms);
        const bool fast = 2 * faster_rays >= int(others.size());
        const bool slow = l.update_ms > max_update;
        fast_rays += fast, slow_updates += slow;
        std::string line = s.name + ": lbvh rays " + rays_of(l) + ", update " + update_of(l) + " (" + counters(l) + ")";
        for (const Config* o : others)
            line += "; " + o->structure + " rays " + rays_of(*o) + ", update " + update_of(*o);
        f.evidence.push_back(line);
    }
    if (tested == 0) {
        f.summary = no_large_scene("", "lbvh and another tree or grid");
        return f;
    }
    f.verdict = verdict(fast_rays == tested && slow_updates == tested, fast_rays + slow_updates > 0);
    f.summary = "LBVH casts at least as fast as half of " + listed(other_names) + " on " + std::to_string(fast_rays) +
                " of " + std::to_string(tested) + " scenes, and has the slowest update on " +
                std::to_string(slow_updates) + " of them.";
    return f;
}

/// `configs`: the dense-ray configurations where the runs have some (`dense`), else the others.
Finding full_sah(const std::vector<Config>& configs, bool dense) {
    Finding f = claim(
        "A DBVH rebuilt with a full SAH builder visits fewer nodes and casts about 40% faster than the "
        "incrementally built one.",
        "§6.4.2, Table 6.4");
    std::vector<double> gains;
    std::map<std::string, std::pair<const Config*, const Config*>> by_scene;  // (incremental, rebuild)
    std::vector<std::string> scenes;  // in the configurations' order: smallest first
    for (const Config& c : configs) {
        if (c.structure != "dbvh" || !c.params.is_object()) continue;
        const std::string mode = c.params.value("mode", "incremental");
        if (!by_scene.count(c.scene)) scenes.push_back(c.scene);
        auto& [inc, reb] = by_scene[c.scene];
        const Config*& slot = mode == "rebuild" ? reb : inc;
        if (!slot || c.ray_ms < slot->ray_ms) slot = &c;
    }
    for (const std::string& scene : scenes) {
        const auto [inc, reb] = by_scene.at(scene);
        if (!inc || !reb || !(inc->ray_ms > 0)) continue;
        const double gain = 1 - reb->ray_ms / inc->ray_ms;
        gains.push_back(gain);
        f.evidence.push_back(scene + ": rays " + rays_of(*inc) + " incremental, " + rays_of(*reb) + " full SAH (" +
                             (gain >= 0 ? "-" : "+") + pct(std::abs(gain)) + "); N_T " + fixed(inc->n_t, 1) +
                             " against " + fixed(reb->n_t, 1) + " per ray");
    }
    if (gains.empty()) {
        f.summary = "The run has no scene with both dbvh mode incremental and mode rebuild.";
        return f;
    }
    const double g = median(gains);
    f.verdict = verdict(g >= 0.25 && g <= 0.55, g > 0.10);
    f.summary = "The full-SAH DBVH casts " + pct(std::abs(g)) + (g >= 0 ? " faster" : " slower") +
                " than the incremental one (median over " + std::to_string(gains.size()) +
                (gains.size() == 1 ? " scene" : " scenes") +
                (dense ? " with dense rays, as the thesis cast them" : ", centre rays; the thesis cast dense rays") +
                "; the thesis: about 40%).";
    return f;
}

Finding hg_memory(const std::vector<Scene>& scenes) {
    Finding f = claim(
        "The hierarchical hash grid needs far more memory than the other structures (about 150 MB against 3 MB "
        "for the BVHs on irreg-l).",
        "§6.2, Table 6.1");
    int tested = 0, largest = 0;
    double min_factor = INFINITY, max_factor = 0;
    std::vector<std::string> other_names = compared_of({Family::grid, Family::bvh});
    std::erase(other_names, "hg");
    for (const Scene& s : scenes) {
        if (s.objects < kLargeScene || !s.best.count("hg")) continue;
        double others = 0;
        std::string line = s.name + ", bytes per object: hg " + fixed(s.best.at("hg").bytes_per_object, 0);
        for (const std::string& o : other_names)
            if (s.best.count(o)) {
                others = std::max(others, s.best.at(o).bytes_per_object);
                line += ", " + o + " " + fixed(s.best.at(o).bytes_per_object, 0);
            }
        if (!(others > 0)) continue;
        ++tested;
        const double factor = s.best.at("hg").bytes_per_object / others;
        largest += factor > 1;
        min_factor = std::min(min_factor, factor), max_factor = std::max(max_factor, factor);
        f.evidence.push_back(line);
    }
    if (tested == 0) {
        f.summary = no_large_scene("", "hg and another structure");
        return f;
    }
    f.verdict = verdict(largest == tested && min_factor >= 2, largest > 0);
    f.summary = "hg holds the most memory per object on " + std::to_string(largest) + " of " + std::to_string(tested) +
                " scenes; its memory per object is " + ratio(min_factor) + " to " + ratio(max_factor) +
                " the largest of " + listed(other_names, "'s") + " (the thesis: about 50x).";
    return f;
}

/// The form the traversal costs are compared under: the thesis' eq. 5.4, fitted for every structure
/// by `rcbench fit` beside its chosen form (a chosen form with more terms moves C_T by what the
/// other terms take, so chosen forms are not comparable across structures).
constexpr const char* kCommonForm = "eq5.4";

/// C_T of the common form per structure, as `rcbench fit` stored it for one run (none without a fit;
/// a fit that did not converge, or whose terms were collinear, is left out).
std::map<std::string, double> common_form_c_t(Database& db, std::int64_t run) {
    return read_fit_coefficients(db, run, "raycast", kCommonForm, "C_T");
}

/// `scenes`: those with dense rays where the runs have some (`dense`), else the others; `stored`:
/// the common form's C_T per structure over the runs that have a fit.
Finding traversal_cost(const std::map<std::string, OverRuns>& stored, const std::vector<Scene>& scenes, bool dense) {
    Finding f = claim(
        "A grid's traversal step is cheaper than a BVH's (a BVH step tests boxes), so grids win where both visit "
        "as many cells as nodes.",
        "§6.4, Table 6.3");
    std::map<std::string, OverRuns> c_t;
    for (const std::string& s : compared_of({Family::grid, Family::bvh}))
        if (stored.count(s) && stored.at(s).median > 0) c_t[s] = stored.at(s);
    auto is_grid = [](const std::string& name) { return find_structure(name).family == Family::grid; };
    const bool grids = std::any_of(c_t.begin(), c_t.end(), [&](const auto& e) { return is_grid(e.first); });
    const bool trees = std::any_of(c_t.begin(), c_t.end(), [&](const auto& e) { return !is_grid(e.first); });
    if (!grids || !trees) {
        f.summary = "No stored fit of eq. 5.4 with a positive C_T for a grid and a BVH: run `rcbench fit` on the run.";
        return f;
    }
    double grid_max = 0, tree_min = INFINITY;
    std::string line = "C_T per step (eq. 5.4 fitted for every structure):";
    for (const auto& [s, over] : c_t) {
        const double v = over.median;
        line += " " + s + " " + fixed(v, 2) + " ns" +
                (over.runs > 1 ? " [" + fixed(over.lo, 2) + "–" + fixed(over.hi, 2) + "]" : "") + ";";
        if (is_grid(s))
            grid_max = std::max(grid_max, v);
        else
            tree_min = std::min(tree_min, v);
    }
    f.evidence.push_back(line);
    // The other half of the thesis' argument: how many steps each takes, and so the traversal's
    // share of a ray (C_T·N_T) on each large scene.
    for (const Scene& sc : scenes) {
        if (sc.objects < kLargeScene) continue;
        std::string per_ray = sc.name + (dense ? " (dense rays)" : "") + ", C_T·N_T per ray:";
        for (const auto& [name, over] : c_t)
            if (sc.best.count(name))
                per_ray += " " + name + " " + fixed(over.median * sc.best.at(name).n_t, 0) + " ns (" +
                           fixed(sc.best.at(name).n_t, 1) + " steps);";
        f.evidence.push_back(per_ray);
    }
    f.verdict = verdict(grid_max < tree_min, false);
    f.summary = grid_max < tree_min ? "Every grid's C_T is below every BVH's (" + fixed(grid_max, 2) + " against " +
                                          fixed(tree_min, 2) + " ns and more)."
                                    : "A grid's C_T (" + fixed(grid_max, 2) + " ns) is not below every BVH's (" +
                                          fixed(tree_min, 2) + " ns).";
    return f;
}

Finding small_scenes(const std::vector<Scene>& scenes) {
    Finding f = claim(
        "On small scenes the structures give little or no speed-up over brute force; as scenes grow it becomes "
        "pronounced.",
        "§6.3");
    std::vector<std::pair<double, double>> speedups;  // (objects, bf / best)
    for (const Scene& s : scenes) {
        const std::vector<const Config*> r = s.ranking();
        const Config* bf = s.baseline();
        if (!bf || r.empty()) continue;
        const double up = bf->frame_ms() / r[0]->frame_ms();
        speedups.emplace_back(s.objects, up);
        f.evidence.push_back(s.name + " (" + fixed(s.objects, 0) + " objects): " + bf->structure + " takes " +
                             ratio(up) + " the time of " + r[0]->structure + ", the best, per frame");
    }
    if (speedups.size() < 2) {
        f.summary = "Needs bf and another structure on at least two scenes.";
        return f;
    }
    std::sort(speedups.begin(), speedups.end());
    const double small = speedups.front().second, large = speedups.back().second;
    f.verdict = verdict(small < 2 && large > small, large > small);
    f.summary = "Per frame, bf takes " + ratio(small) + " the best structure's time on the smallest scene (" +
                fixed(speedups.front().first, 0) + " objects) and " + ratio(large) + " on the largest (" +
                fixed(speedups.back().first, 0) + ").";
    return f;
}

Finding most_promising(const std::vector<Scene>& scenes) {
    Finding f = claim(
        "Weighing query against update speed, HG and DBVH are the most promising choices, especially as the "
        "irregular part of a scene grows.",
        "chapter 8");
    int tested = 0, both = 0, one = 0;
    for (const Scene& s : scenes) {
        if (s.category != "irregular" || s.objects < kLargeScene) continue;
        const std::vector<const Config*> r = s.ranking();
        if (r.size() < 3) continue;
        ++tested;
        const bool a = r[0]->structure == "hg" || r[0]->structure == "dbvh";
        const bool b = r[1]->structure == "hg" || r[1]->structure == "dbvh";
        both += a && b, one += a || b;
        f.evidence.push_back(s.name + ": fastest " + r[0]->structure + ", then " + r[1]->structure + " (" +
                             ratio(r[1]->frame_ms() / r[0]->frame_ms()) + ")");
    }
    if (tested == 0) {
        f.summary = no_large_scene("irregular ", "three structures");
        return f;
    }
    f.verdict = verdict(both == tested, one > 0);
    f.summary = "hg and dbvh are the two fastest per frame on " + std::to_string(both) + " of " +
                std::to_string(tested) + " large irregular scenes, and one of them is among the two on " +
                std::to_string(one) + ".";
    return f;
}

/// Every claim on one set of configurations (one run's, or the medians over runs) and C_T.
std::vector<Finding> evaluate_on(const std::vector<Config>& configs, const std::map<std::string, OverRuns>& c_t) {
    std::vector<Config> centre, dense;
    for (const Config& c : configs) (dense_rays(c) ? dense : centre).push_back(c);
    const std::vector<Scene> scenes = scenes_of(centre);
    return {best_on(scenes, "uniform", "ug", "The uniform grid does very well on uniform scenes.", "§6.3, Table 6.2"),
            best_on(scenes, "irregular", "hg",
                    "The hierarchical hash grid performs best on the larger irregular scenes.", "§6.3, Table 6.2"),
            lbvh_trade(scenes),
            full_sah(dense.empty() ? centre : dense, !dense.empty()),
            hg_memory(scenes),
            traversal_cost(c_t, dense.empty() ? scenes : scenes_of(dense), !dense.empty()),
            small_scenes(scenes),
            most_promising(scenes)};
}

/// "bf defaults; ug density 1.0/4.0/16.0; dbvh mode incremental/rebuild": per compared structure
/// the parameters its measured configurations set apart from its defaults, each one's values in
/// order (numbers as numbers).
std::string configurations_line(const std::vector<Config>& configs) {
    std::string out;
    for (const std::string& name : findings_structures()) {
        std::map<std::string, std::set<nlohmann::json>> values;  // key -> distinct values, numbers as numbers
        bool measured = false;
        const nlohmann::json defaults = find_structure(name).defaults();
        for (const Config& c : configs) {
            if (c.structure != name || !c.params.is_object()) continue;
            measured = true;
            for (const auto& [key, value] : c.params.items()) values[key].insert(value);
        }
        if (!measured) continue;
        auto text = [](const nlohmann::json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); };
        std::string set;
        for (const auto& [key, distinct] : values) {
            std::vector<std::string> seen;
            for (const nlohmann::json& v : distinct) seen.push_back(text(v));
            const bool is_default = seen.size() == 1 && defaults.contains(key) && text(defaults[key]) == seen.front();
            if (!is_default) set += (set.empty() ? "" : ", ") + key + " " + join(seen, "/");
        }
        out += (out.empty() ? "" : "; ") + name + " " + (set.empty() ? "defaults" : set);
    }
    return out;
}

/// How a run's figure of a configuration comes from its repetitions, for the page's preamble.
std::string repetitions_sentence(OverRepetitions how) {
    return std::string("A run's time of a configuration is ") + repetitions_phrase(how) + ". ";
}

/// The runs' configurations: each run's, and the medians over runs.
struct RunsData {
    std::vector<std::vector<Config>> per_run;
    std::vector<std::map<std::string, OverRuns>> c_t_per_run;
    std::vector<Config> merged;
    std::map<std::string, OverRuns> c_t;
};

RunsData load_runs(const std::vector<FindingsRun>& runs, OverRepetitions how) {
    RunsData d;
    std::map<std::string, std::vector<double>> c_t;
    for (const FindingsRun& r : runs) {
        d.per_run.push_back(load_configs(*r.db, r.run, how));
        std::map<std::string, OverRuns> one;
        for (const auto& [name, v] : common_form_c_t(*r.db, r.run)) {
            one[name] = over_runs({v});
            c_t[name].push_back(v);
        }
        d.c_t_per_run.push_back(std::move(one));
    }
    d.merged = merge_runs(d.per_run);
    for (const auto& [name, v] : c_t) d.c_t[name] = over_runs(v);
    return d;
}

/// The claims on the medians over runs, each with its verdict on every run alone.
std::vector<Finding> evaluate_loaded(const RunsData& d) {
    std::vector<Finding> out = evaluate_on(d.merged, d.c_t);
    for (std::size_t r = 0; r < d.per_run.size(); ++r) {
        const std::vector<Finding> alone = evaluate_on(d.per_run[r], d.c_t_per_run[r]);
        for (std::size_t k = 0; k < out.size(); ++k) out[k].per_run.push_back(alone[k].verdict);
    }
    return out;
}

}  // namespace

std::vector<std::string> findings_structures() {
    return structure_names([](const StructureInfo& info) { return info.origin != Origin::peer; });
}

const char* verdict_name(Finding::Verdict v) {
    switch (v) {
        case Finding::Verdict::confirmed:
            return "confirmed";
        case Finding::Verdict::partly:
            return "partly confirmed";
        case Finding::Verdict::refuted:
            return "refuted";
        case Finding::Verdict::untested:
            return "not tested by this run";
    }
    return "";
}

std::vector<Finding> evaluate_findings(const std::vector<FindingsRun>& runs, OverRepetitions how) {
    if (runs.empty()) throw std::logic_error("evaluate_findings: no run");
    return evaluate_loaded(load_runs(runs, how));
}

std::vector<Finding> evaluate_findings(Database& db, std::int64_t run, OverRepetitions how) {
    return evaluate_findings({{&db, run}}, how);
}

std::string findings_markdown(const std::vector<FindingsRun>& runs, OverRepetitions how) {
    if (runs.empty()) throw std::logic_error("findings_markdown: no run");
    const RunsData d = load_runs(runs, how);
    const std::vector<Finding> findings = evaluate_loaded(d);
    std::ostringstream md;
    md << "# Findings: the thesis' conclusions against rcbench's measurements\n\n";
    std::string experiment;
    std::vector<std::string> provenance;
    for (const FindingsRun& r : runs) {
        const std::optional<StoredRun> info = read_stored_run(*r.db, r.run);
        if (!info) continue;
        experiment = info->experiment;
        provenance.push_back("run " + std::to_string(r.run) + " (uuid " + info->uuid + ", started " + info->started_at +
                             ", commit " + info->git_commit + ", " + info->cpu_model + ", " + info->compiler + ")");
    }
    const bool several = runs.size() > 1;
    if (several) {
        md << "Computed by `rcbench findings` from " << runs.size() << " independent runs of experiment `" << experiment
           << "`:\n\n";
        for (const std::string& p : provenance) md << "- " << p << "\n";
        md << "\n";
    } else {
        md << "Computed by `rcbench findings` from experiment `" << experiment << "`"
           << (provenance.empty() ? "" : ", " + provenance.front()) << ". ";
    }
    md << "Thesis: Guo & Liao (2023), see [reference.md](reference.md). To make it again: `rcbench run` the "
          "experiment (once per run), `rcbench fit` each run (the traversal-cost claim reads the fit), then "
          "`rcbench findings` with every run.\n\n";
    md << "Each claim is checked on rcbench's own structures (" << join(findings_structures(), ", ")
       << "; the registry's structures that are not another library's), each at its fastest measured "
          "configuration per scene; per frame = update + ray cast (thesis eq. 5.5). Configurations measured: "
       << configurations_line(d.merged) << ". " << repetitions_sentence(how)
       << (several ? "Below, the median over the runs of each run's figure, with [lowest–highest] over the runs "
                     "for times, and each verdict says how many runs alone give it. "
                   : "")
       << "Claims about winners are read on scenes of " << fixed(kLargeScene, 0) << " objects or more; within "
       << pct(kNearBest) << " of the fastest counts as partly confirmed. ";
    const bool dense = std::any_of(d.merged.begin(), d.merged.end(), dense_rays);
    md << (dense ? "Tables 6.3 and 6.4 are read on the scenes with dense rays, as the thesis cast them (§6.4); the "
                   "other claims on the rest."
                 : "The runs have no scene with dense rays, which the thesis cast for Tables 6.3 and 6.4 (§6.4); "
                   "those claims are read on centre rays.")
       << "\n\n";
    for (const Finding& f : findings) {
        md << "## " << f.claim << "\n\n"
           << "Thesis " << f.source << ". **" << verdict_name(f.verdict) << "**: " << f.summary;
        if (f.per_run.size() > 1) {
            const auto same = std::count(f.per_run.begin(), f.per_run.end(), f.verdict);
            md << " Each run alone: " << same << " of " << f.per_run.size() << " give this verdict";
            if (std::size_t(same) != f.per_run.size()) {
                std::vector<std::string> names;
                for (Finding::Verdict v : f.per_run) names.push_back(verdict_name(v));
                md << " (" << join(names, ", ") << ")";
            }
            md << ".";
        }
        md << "\n\n";
        for (const std::string& e : f.evidence) md << "- " << e << "\n";
        if (!f.evidence.empty()) md << "\n";
    }
    return md.str();
}

}  // namespace rcb
