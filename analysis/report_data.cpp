#include "analysis/report_data.h"

#include <algorithm>
#include <functional>
#include <map>
#include <set>
#include <tuple>

#include <nlohmann/json.hpp>

#include "analysis/query_kinds.h"
#include "core/base/statistics.h"
#include "accel/registry.h"
#include "core/base/error.h"
#include "core/scene/generate/physics.h"
#include "core/scene/phases.h"
#include "sim/simulator.h"

namespace rcb::report {
namespace {

/// The scene's recording and window from its spec's "measure" (runner/experiment.h, SceneSpec::key):
/// a phase's scene is named after its entry with "-<phase>" appended.
void read_window(Entry& e, const std::string& spec) {
    const std::vector<std::string> phases = motion_phase_names();
    e.recording = e.scene;
    e.window = "every frame";
    e.window_order = int(phases.size()) + 1;
    const nlohmann::json j = nlohmann::json::parse(spec, nullptr, false);
    if (!j.is_object() || !j.contains("measure") || !j["measure"].is_object()) return;
    const nlohmann::json& m = j["measure"];
    const std::int64_t stride =
        m.contains("stride") && m["stride"].is_number_integer() ? m["stride"].get<std::int64_t>() : 1;
    const std::string every = stride > 1 ? ", every " + std::to_string(stride) + " frames" : "";
    if (m.contains("phase") && m["phase"].is_string()) {
        const std::string phase = m["phase"].get<std::string>();
        e.window = phase + every;
        e.window_order = int(std::find(phases.begin(), phases.end(), phase) - phases.begin());
        const std::string suffix = "-" + phase;
        if (e.scene.size() > suffix.size() && e.scene.ends_with(suffix))
            e.recording = e.scene.substr(0, e.scene.size() - suffix.size());
    } else if (m.contains("start_frame")) {
        e.window = "from frame " + m["start_frame"].dump() + every;
        e.window_order = int(phases.size());
    }
}

/// Per cell, per query kind: the batch times (ns) of its measured frames; empty for a run without kinds.
std::map<std::int64_t, std::map<std::string, std::vector<double>>> kind_batch_times(Database& db, std::int64_t run) {
    std::map<std::int64_t, std::map<std::string, std::vector<double>>> out;
    if (!run_has_frame_kinds(db, run)) return out;
    for (const FrameKindRow& r : read_frame_kinds(db, run)) out[r.cell_id][r.kind].push_back(r.raycast_ns);
    return out;
}

std::vector<Entry> load_entries(Database& db, std::int64_t run) {
    struct Acc {
        Entry e;
        std::vector<double> build, update, raycast, memory;
        std::map<std::string, std::vector<double>> kinds;  ///< per kind, each repetition's median batch (ms)
    };
    const auto kind_times = kind_batch_times(db, run);
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
        read_window(e, r.spec);
        if (const auto k = kind_times.find(r.id); k != kind_times.end())
            for (const auto& [kind, ns] : k->second) a.kinds[kind].push_back(spread_of(ns).median / 1e6);
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
        for (const auto& [kind, ms] : a.kinds) a.e.kind_raycast_ms[kind] = spread_of(ms).median;
        out.push_back(a.e);
    }
    if (out.empty()) throw InputError("run " + std::to_string(run) + " has no measured cells to report");
    return out;
}

RunHead load_run_head(Database& db, std::int64_t run) {
    const std::optional<StoredRun> r = read_stored_run(db, run);
    if (!r) throw InputError("no run " + std::to_string(run));
    return {r->experiment, r->git_commit, r->cpu_model + " (" + std::to_string(r->cores) + " cores)", r->started_at,
            r->binary + (r->binary_id.empty() ? "" : " (build " + r->binary_id.substr(0, 12) + ")")};
}

History load_run_history(Database& db, std::int64_t run, const std::string& experiment) {
    History h;
    h.query.experiment = experiment;
    // The runs of the program that made this one: another program's (its own structures, its own
    // build) are another history.
    if (const std::optional<StoredRun> r = read_stored_run(db, run)) h.query.binary = r->binary;
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
    if (run_has_frame_kinds(db, run)) d.kind_frames = load_kind_observations(db, run);
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

namespace {

/// The fastest own configuration on `here` (one scene's entries) and each peer structure's fastest,
/// per frame for every ray (`kind` empty) or for one kind's batch.
PeerComparison compare_on(const std::vector<const Entry*>& here, const std::string& kind) {
    PeerComparison c;
    c.scene = here.front();
    c.kind = kind;
    for (const Entry* e : here) {
        const double ms = e->frame_ms(kind);
        if (!std::isfinite(ms)) continue;
        const StructureInfo* info = registered_structure(e->structure);
        if (!info || info->origin != Origin::peer) {
            if (!c.own || ms < c.own_ms) c.own = e, c.own_ms = ms;
            continue;
        }
        const auto peer = std::find_if(c.peers.begin(), c.peers.end(),
                                       [&](const PeerBest& p) { return p.structure == e->structure; });
        if (peer == c.peers.end())
            c.peers.push_back({e->structure, e, ms});
        else if (ms < peer->ms)
            *peer = {e->structure, e, ms};
    }
    for (std::size_t i = 1; i < c.peers.size(); ++i)
        if (c.peers[i].ms < c.peers[c.best_peer].ms) c.best_peer = i;
    return c;
}

/// The comparisons on the scenes of `es` that `keep` accepts.
PeerSection comparisons_on(const Entries& es, const std::function<bool(const Entry&)>& keep) {
    PeerSection p;
    for (const Entry& e : es.all)
        if (keep(e)) p.entries.push_back(&e);
    const std::vector<std::string> generators = physics_generators(), structures = structure_names();
    const auto rank = [](const std::vector<std::string>& list, const std::string& name) {
        return std::find(list.begin(), list.end(), name) - list.begin();
    };
    std::stable_sort(p.entries.begin(), p.entries.end(), [&](const Entry* a, const Entry* b) {
        return std::make_tuple(rank(generators, a->category), a->objects, a->recording, a->window_order, a->window,
                               a->scene, rank(structures, a->structure), a->label) <
               std::make_tuple(rank(generators, b->category), b->objects, b->recording, b->window_order, b->window,
                               b->scene, rank(structures, b->structure), b->label);
    });
    for (const char* kind : kQueryKindNames)
        if (std::any_of(p.entries.begin(), p.entries.end(),
                        [&](const Entry* e) { return e->kind_raycast_ms.count(kind) != 0; }))
            p.kinds.push_back(kind);
    for (std::size_t first = 0; first < p.entries.size();) {
        std::size_t end = first;
        while (end < p.entries.size() && p.entries[end]->scene == p.entries[first]->scene) ++end;
        const std::vector<const Entry*> here(p.entries.begin() + std::ptrdiff_t(first),
                                             p.entries.begin() + std::ptrdiff_t(end));
        p.comparisons.push_back(compare_on(here, ""));
        for (const std::string& kind : p.kinds) p.comparisons.push_back(compare_on(here, kind));
        first = end;
    }
    return p;
}

}  // namespace

PeerSection physics_section(const Entries& es) {
    return comparisons_on(es, [](const Entry& e) { return is_physics_generator(e.category); });
}

PeerSection peer_section(const Entries& es) {
    std::set<std::string> with_peer;
    for (const Entry& e : es.all)
        if (const StructureInfo* info = registered_structure(e.structure); info && info->origin == Origin::peer)
            with_peer.insert(e.scene);
    return comparisons_on(
        es, [&](const Entry& e) { return !is_physics_generator(e.category) && with_peer.count(e.scene); });
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
