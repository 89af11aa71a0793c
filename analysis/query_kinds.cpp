#include "analysis/query_kinds.h"

#include <algorithm>
#include <map>
#include <set>
#include <tuple>

#include "core/base/statistics.h"
#include "accel/model/counter_fields.h"
#include "core/scene/scene.h"
#include "runner/results_reader.h"

namespace rcb {
namespace {

/// The rank of a kind's name in QueryKind order (all, closest, any), for sorting.
int kind_rank(const std::string& kind) {
    return int(std::find(std::begin(kQueryKindNames), std::end(kQueryKindNames), kind) - std::begin(kQueryKindNames));
}

/// One frame_kind row: the kind, its rays and ray-cast time, and its counters by column name.
struct KindRow {
    std::string kind;
    double rays = 0, raycast_ns = 0;
    std::map<std::string, double> counters;
};

/// The run's frame_kind rows of measured frames by (cell, frame).
std::map<std::pair<std::int64_t, std::int64_t>, std::vector<KindRow>> kind_rows(Database& db, std::int64_t run) {
    std::map<std::pair<std::int64_t, std::int64_t>, std::vector<KindRow>> out;
    for (FrameKindRow& row : read_frame_kinds(db, run)) {
        KindRow r{std::move(row.kind), row.rays, row.raycast_ns, {}};
        for (std::size_t i = 0; i < kCounterFields.size(); ++i) r.counters[kCounterFields[i].name] = row.counters[i];
        out[{row.cell_id, row.frame}].push_back(std::move(r));
    }
    for (auto& [key, rows] : out)
        std::sort(rows.begin(), rows.end(),
                  [](const KindRow& a, const KindRow& b) { return kind_rank(a.kind) < kind_rank(b.kind); });
    return out;
}

/// `frame` as the observation of one kind's batch: rays, time and per-ray counters of `row`.
FrameObservation kind_observation(const FrameObservation& frame, const KindRow& row) {
    FrameObservation o = frame;
    o.kind = row.kind;
    o.rays = row.rays;
    o.raycast_ns = row.raycast_ns;
    for (const FrameCounter& c : frame_counters()) {
        if (c.scale != CounterScale::per_ray) continue;
        const auto it = row.counters.find(c.alias);
        if (it == row.counters.end()) throw std::logic_error("frame_kind has no column " + std::string(c.alias));
        o.*(c.field) = row.rays > 0 ? it->second / row.rays : 0.0;
    }
    return o;
}

ValidationSplit kinds_split(const std::vector<FrameObservation>& frames, const std::set<std::string>& from,
                            const std::set<std::string>& to) {
    const auto names = [](const std::set<std::string>& kinds) {
        std::vector<std::string> sorted(kinds.begin(), kinds.end());
        std::sort(sorted.begin(), sorted.end(),
                  [](const std::string& a, const std::string& b) { return kind_rank(a) < kind_rank(b); });
        return join(sorted, "+");
    };
    ValidationSplit s{kKindTransferGroup, names(from) + " -> " + names(to), {}, {}};
    for (std::size_t i = 0; i < frames.size(); ++i) {
        if (from.count(frames[i].kind)) s.train.push_back(i);
        if (to.count(frames[i].kind)) s.test.push_back(i);
    }
    return s;
}

}  // namespace

std::vector<FrameObservation> load_kind_observations(Database& db, std::int64_t run) {
    // Every repetition's frames: a kind's batch is matched to its own frame row, so the frames are
    // not collapsed to their fastest repetition here.
    const std::vector<FrameObservation> frames = load_observations(db, run, OverRepetitions::median);
    // The frames' keys in load_observations' order (its query's WHERE and ORDER BY).
    const std::vector<std::pair<std::int64_t, std::int64_t>> keys = read_measured_frame_keys(db, run);
    const auto rows = kind_rows(db, run);
    std::vector<FrameObservation> out;
    std::map<std::pair<int, std::string>, int> groups;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const FrameObservation& f = frames[i];
        if (i >= keys.size()) throw std::logic_error("the run's frames changed while they were read");
        const auto it = rows.find(keys[i]);
        if (it == rows.end()) {
            out.push_back(f);
            out.back().kind = kQueryKindNames[int(QueryKind::all)];
        } else {
            for (const KindRow& r : it->second) out.push_back(kind_observation(f, r));
        }
    }
    for (FrameObservation& o : out)
        o.config_group = groups.emplace(std::make_pair(o.config_group, o.kind), int(groups.size())).first->second;
    return out;
}

std::vector<KindCell> kind_cells(const std::vector<StructureModels>& models,
                                 const std::vector<FrameObservation>& kind_frames) {
    std::map<std::string, const StructureModels*> by_structure;
    for (const StructureModels& m : models) by_structure[m.structure] = &m;
    std::vector<int> order;
    std::map<int, std::vector<const FrameObservation*>> cells;
    for (const FrameObservation& f : kind_frames) {
        if (f.rays <= 0) continue;
        auto& fs = cells[f.config_group];
        if (fs.empty()) order.push_back(f.config_group);
        fs.push_back(&f);
    }
    std::vector<KindCell> out;
    for (int group : order) {
        const std::vector<const FrameObservation*>& fs = cells[group];
        const FrameObservation& first = *fs.front();
        KindCell c{first.structure, first.params, first.scene, first.kind.empty() ? "all" : first.kind};
        const auto m = by_structure.find(first.structure);
        const bool model = m != by_structure.end() && m->second->predict_ray;
        std::vector<double> rays, ns, per_query, predicted, predicted_per_query;
        for (const FrameObservation* f : fs) {
            rays.push_back(f->rays);
            ns.push_back(f->raycast_ns);
            per_query.push_back(f->raycast_ns / f->rays);
            if (!model) continue;
            const double per_ray = m->second->predict_ray(*f);
            predicted_per_query.push_back(per_ray);
            predicted.push_back(per_ray * f->rays);
        }
        c.rays = quantile(rays, 0.5);
        c.raycast_ns = quantile(ns, 0.5);
        c.ns_per_query = quantile(per_query, 0.5);
        c.predicted_raycast_ns = quantile_or_nan(predicted, 0.5);
        c.predicted_ns_per_query = quantile_or_nan(predicted_per_query, 0.5);
        c.error = relative_error(c.predicted_raycast_ns, c.raycast_ns);
        out.push_back(std::move(c));
    }
    return out;
}

std::vector<KindError> kind_errors(const std::vector<KindCell>& cells) {
    // Per (structure, kind): its cells and the finite errors among them.
    std::map<std::tuple<std::string, int, std::string>, std::pair<std::size_t, std::vector<double>>> errors;
    for (const KindCell& c : cells) {
        auto& [n, finite] = errors[std::make_tuple(c.structure, kind_rank(c.kind), c.kind)];
        ++n;
        if (std::isfinite(c.error)) finite.push_back(c.error);
    }
    std::vector<KindError> out;
    for (const auto& [key, e] : errors)
        out.push_back({std::get<0>(key), std::get<2>(key), e.first, quantile(e.second, 0.5)});
    return out;
}

std::vector<KindSummary> kind_summaries(const std::vector<StructureModels>& models,
                                        const std::vector<FrameObservation>& kind_frames) {
    std::map<std::string, const StructureModels*> by_structure;
    for (const StructureModels& m : models) by_structure[m.structure] = &m;
    std::vector<KindSummary> out;
    for (const KindError& e : kind_errors(kind_cells(models, kind_frames))) {
        KindSummary s;
        s.structure = e.structure, s.kind = e.kind;
        s.cells = e.cells;
        s.median_error = e.median_error;
        const auto m = by_structure.find(e.structure);
        const bool model = m != by_structure.end() && m->second->predict_ray;
        std::vector<double> measured, predicted;
        for (const FrameObservation& f : kind_frames) {
            if (f.structure != e.structure || f.kind != e.kind || f.rays <= 0) continue;
            measured.push_back(f.raycast_ns / f.rays);
            predicted.push_back(model ? m->second->predict_ray(f) : NAN);
        }
        s.batches = measured.size();
        s.ns_per_query = quantile(measured, 0.5);
        s.predicted_ns_per_query = quantile_or_nan(predicted, 0.5);
        out.push_back(std::move(s));
    }
    return out;
}

std::vector<ValidationGroup> validate_frozen_kinds(const std::vector<StructureModels>& models,
                                                   const std::vector<FrameObservation>& kind_frames,
                                                   const BootstrapOptions& options) {
    std::map<std::string, std::string> forms;  // structure -> its chosen ray-cast form, where it has a model
    for (const StructureModels& m : models)
        if (const CandidateModel* c = m.chosen("raycast"); c && m.predict_ray) forms[m.structure] = c->name;
    const std::vector<KindCell> cells = kind_cells(models, kind_frames);
    std::vector<ValidationGroup> out;
    for (const char* kind : kQueryKindNames) {
        ValidationGroup g;
        g.name = std::string(kKindGroupPrefix) + kind;
        g.splits = {g.name};
        for (const KindCell& k : cells) {
            if (k.kind != kind) continue;
            CellPrediction c;
            c.split = g.name;
            c.structure = k.structure, c.scene = k.scene, c.params = k.params;
            const auto form = forms.find(k.structure);
            if (form != forms.end()) c.raycast_model = form->second;
            c.raycast_ns = k.raycast_ns;
            c.predicted_raycast_ns = k.predicted_raycast_ns;
            c.raycast_error = k.error;
            g.cells.push_back(std::move(c));
        }
        if (g.cells.empty()) continue;
        g.structures = summarize(g.cells, options);
        out.push_back(std::move(g));
    }
    return out;
}

std::vector<ValidationSplit> kind_transfer_splits(const std::vector<FrameObservation>& kind_frames) {
    std::set<std::string> kinds;
    for (const FrameObservation& f : kind_frames) kinds.insert(f.kind);
    std::vector<ValidationSplit> out;
    if (kinds.size() < 2) return out;
    const std::string all = kQueryKindNames[int(QueryKind::all)];
    std::vector<std::string> in_order;  // QueryKind order: all, closest, any
    for (const char* k : kQueryKindNames)
        if (kinds.count(k)) in_order.push_back(k);
    if (kinds.count(all)) {
        std::set<std::string> others = kinds;
        others.erase(all);
        for (const std::string& k : in_order)
            if (k != all) out.push_back(kinds_split(kind_frames, {all}, {k}));
        out.push_back(kinds_split(kind_frames, others, {all}));
    } else {
        for (const std::string& k : in_order) {
            std::set<std::string> others = kinds;
            others.erase(k);
            out.push_back(kinds_split(kind_frames, {k}, others));
        }
    }
    return out;
}

}  // namespace rcb
