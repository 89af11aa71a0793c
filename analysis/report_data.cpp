#include "analysis/report_data.h"

#include <algorithm>
#include <map>

#include <nlohmann/json.hpp>

#include "analysis/query_kinds.h"
#include "core/base/statistics.h"
#include "core/accel/registry.h"
#include "core/base/error.h"
#include "core/sim/simulator.h"

namespace rcb::report {
namespace {

std::vector<Entry> load_entries(Database& db, std::int64_t run) {
    struct Acc {
        Entry e;
        std::vector<double> build, update, raycast, memory;
    };
    std::map<std::pair<std::string, std::string>, Acc> acc;  // (scene, label)
    std::vector<std::pair<std::string, std::string>> order;
    for (const CellTotalsRow& r : read_cell_totals(db, run)) {
        const std::string label = config_label(r.structure, r.params);
        const auto key = std::make_pair(r.scene, label);
        auto [it, fresh] = acc.try_emplace(key);
        if (fresh) order.push_back(key);
        Acc& a = it->second;
        Entry& e = a.e;
        e.scene = r.scene;
        e.category = scene_category(r.spec);
        e.structure = r.structure;
        e.params = r.params;
        e.label = label;
        e.objects = r.objects;
        a.build.push_back(r.build_ns / 1e6);
        a.update.push_back(r.update_ns / 1e6);
        a.raycast.push_back(r.raycast_ns / 1e6);
        a.memory.push_back(e.objects > 0 ? r.memory_bytes / e.objects : 0);
        e.hits += r.hits, e.missed += r.missed, e.extra += r.extra, e.duplicate += r.duplicate;
        e.returned += r.returned, e.correct += r.correct, e.relevant += r.relevant;
        e.verified = e.verified && r.verified;
        if (r.repetition == 0)
            for (const FrameSeriesRow& f : read_frame_series(db, r.id)) {
                e.frame_raycast_ms.push_back(f.raycast_ns / 1e6);
                e.frame_sah.push_back(f.sah_cost);
            }
    }
    std::vector<Entry> out;
    for (const auto& key : order) {
        Acc& a = acc[key];
        a.e.build_ms = spread_of(a.build).median;
        a.e.update_ms = spread_of(a.update).median;
        a.e.raycast_ms = spread_of(a.raycast).median;
        a.e.memory_per_object = spread_of(a.memory).median;
        out.push_back(a.e);
    }
    if (out.empty()) throw InputError("run " + std::to_string(run) + " has no measured cells to report");
    return out;
}

RunHead load_run_head(Database& db, std::int64_t run) {
    const std::optional<StoredRun> r = read_stored_run(db, run);
    if (!r) throw InputError("no run " + std::to_string(run));
    return {r->experiment, r->git_commit, r->cpu_model + " (" + std::to_string(r->cores) + " cores)", r->started_at};
}

History load_run_history(Database& db, std::int64_t run, const std::string& experiment) {
    History h;
    h.query.experiment = experiment;
    h.query.up_to_run = run;
    try {
        h.cast = load_history(db, h.query);
        HistoryQuery update = h.query;
        update.metric = "update";
        h.update = load_history(db, update);
    } catch (const InputError&) {
        h.cast.clear(), h.update.clear();  // no frame measured outside warm-up: no history to draw
    }
    return h;
}

std::vector<SceneMotion> load_scene_motion(Database& db, std::int64_t run) {
    std::vector<std::string> order;
    std::map<std::string, std::vector<double>> shares;
    for (const FrameChangesRow& r : read_scene_changes(db, run)) {
        if (!shares.count(r.scene)) order.push_back(r.scene);
        shares[r.scene].push_back(r.objects > 0 ? r.changes / r.objects : 0.0);
    }
    std::vector<SceneMotion> out;
    for (const std::string& scene : order) {
        const std::vector<double>& v = shares[scene];
        out.push_back({scene, quantile(v, 0.1), quantile(v, 0.5), quantile(v, 0.9)});
    }
    return out;
}

}  // namespace

std::string config_label(const std::string& structure, const std::string& params_text) {
    const nlohmann::json params = nlohmann::json::parse(params_text, nullptr, false);
    std::string changed;
    try {
        const nlohmann::json defaults = find_structure(structure).defaults();
        for (const auto& [k, v] : params.items())
            if (!defaults.contains(k) || defaults[k] != v)
                changed += (changed.empty() ? "" : ",") + k + "=" + (v.is_string() ? v.get<std::string>() : v.dump());
    } catch (const InputError&) {
        changed = params.dump();  // a structure this binary does not know: show everything
    }
    return changed.empty() ? structure : structure + " " + changed;
}

ReportData load_report_data(Database& db, std::int64_t run) {
    ReportData d;
    d.entries = load_entries(db, run);
    d.head = load_run_head(db, run);
    d.slow = slow_cells(db, run);
    d.frames = load_observations(db, run);
    d.model_inputs = load_model_inputs(db, run);
    d.noise = noise_floor(db, run);
    d.findings = evaluate_findings(db, run);
    d.history = load_run_history(db, run, d.head.experiment);
    d.motion = load_scene_motion(db, run);
    if (run_has_query_kinds(db, run)) d.kind_frames = load_kind_observations(db, run);
    return d;
}

std::pair<std::string, const Entry*> best_on_largest(const Entries& es, const std::string& category) {
    std::string scene;
    double most_objects = -1;
    for (const Entry& e : es.all)
        if (e.category == category && e.objects > most_objects) most_objects = e.objects, scene = e.scene;
    const Entry* best = nullptr;
    for (const std::string& l : es.labels)
        for (const Entry& e : es.all)
            if (e.category == category && e.label == l && e.scene == scene &&
                (!best || e.total_ms() < best->total_ms()))
                best = &e;
    return {scene, best};
}

std::pair<std::string, double> largest_drift(const Entries& es) {
    double worst_drift = 0;
    std::string worst;
    for (const Entry& e : es.all) {
        if (e.scene != es.largest || e.frame_raycast_ms.empty()) continue;
        const std::size_t q = std::max<std::size_t>(1, e.frame_raycast_ms.size() / 4);
        const double first =
            spread_of({e.frame_raycast_ms.begin(), e.frame_raycast_ms.begin() + std::ptrdiff_t(q)}).median;
        const double last = spread_of({e.frame_raycast_ms.end() - std::ptrdiff_t(q), e.frame_raycast_ms.end()}).median;
        if (first > 0 && std::abs(last / first - 1) > std::abs(worst_drift))
            worst_drift = last / first - 1, worst = e.label;
    }
    return {worst, worst_drift};
}

std::string growth_category(const std::vector<Entry>& entries) {
    std::map<std::string, std::vector<double>> counts;
    for (const Entry& e : entries) {
        std::vector<double>& v = counts[e.category];
        if (std::find(v.begin(), v.end(), e.objects) == v.end()) v.push_back(e.objects);
    }
    std::string category;
    std::size_t most_counts = 1;
    for (const auto& [c, v] : counts)
        if (v.size() > most_counts) most_counts = v.size(), category = c;
    return category;
}

const Entry* baseline_on(const std::vector<Entry>& entries, const std::string& scene, bool default_params_only) {
    for (const Entry& e : entries) {
        const StructureInfo* info = registered_structure(e.structure);
        if (e.scene != scene || !info || info->family != Family::scan) continue;
        if (!default_params_only || e.label == e.structure) return &e;
    }
    return nullptr;
}

FailureCell failure_cell(const std::vector<Entry>& entries, const Entry& e) {
    FailureCell c;
    c.mismatches = e.missed + e.extra + e.duplicate;
    const Entry* bf = baseline_on(entries, e.scene, false);
    if (bf && bf->total_ms() > 0) c.vs_bf = e.total_ms() / bf->total_ms();
    // The benign scene of a failure scene: generated irregular (else uniform) with as many objects.
    for (const char* kind : {"irregular", "uniform"}) {
        for (const Entry& b : entries)
            if (b.category == kind && b.label == e.label && b.objects == e.objects) {
                if (b.total_ms() > 0) c.vs_benign = e.total_ms() / b.total_ms();
                return c;
            }
    }
    return c;
}

std::vector<SahChange> sah_changes(const Entries& es) {
    std::vector<SahChange> out;
    for (const Entry& e : es.all) {
        if (e.scene != es.largest) continue;
        Series s{e.label, {}, {}, {}, true, es.style_of(e.label)};
        for (std::size_t f = 0; f < e.frame_sah.size(); ++f)
            if (std::isfinite(e.frame_sah[f])) s.x.push_back(double(f + 1)), s.y.push_back(e.frame_sah[f]);
        if (s.x.empty()) continue;
        const double change = s.y.front() > 0 ? s.y.back() / s.y.front() - 1 : 0;
        out.push_back({e.label, change, s});
    }
    return out;
}

}  // namespace rcb::report
