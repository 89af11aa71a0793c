#include "analysis/validation.h"

#include <algorithm>
#include <functional>
#include <set>

#include "analysis/model_terms.h"
#include "core/base/random.h"
#include "runner/results_reader.h"
#include "runner/results_writer.h"

namespace rcb {
namespace {

/// One split per distinct value of `key` (in order of first appearance), that value's frames
/// predicted from the rest; none when every frame has the same value.
std::vector<ValidationSplit> leave_each_out(const std::vector<FrameObservation>& frames, const std::string& group,
                                            const std::function<std::string(const FrameObservation&)>& key) {
    std::vector<std::string> keys;
    std::map<std::string, std::size_t> index;
    std::vector<std::size_t> of(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const auto [it, added] = index.emplace(key(frames[i]), keys.size());
        if (added) keys.push_back(it->first);
        of[i] = it->second;
    }
    std::vector<ValidationSplit> out;
    if (keys.size() < 2) return out;
    for (std::size_t k = 0; k < keys.size(); ++k) {
        ValidationSplit s{group, keys[k], {}, {}};
        for (std::size_t i = 0; i < frames.size(); ++i) (of[i] == k ? s.test : s.train).push_back(i);
        out.push_back(std::move(s));
    }
    return out;
}

std::string ray_mode_of(const FrameObservation& f) { return f.ray_mix.empty() ? "unspecified" : f.ray_mix; }

/// The frames whose `key` is in `from` as train, those whose key is in `to` as test.
ValidationSplit transfer_split(const std::vector<FrameObservation>& frames, const std::set<std::string>& from,
                               const std::set<std::string>& to) {
    ValidationSplit s;
    s.name = "ray modes " + join(from, "+") + " -> " + join(to, "+");
    s.group = s.name;
    for (std::size_t i = 0; i < frames.size(); ++i) {
        const std::string mode = ray_mode_of(frames[i]);
        if (from.count(mode)) s.train.push_back(i);
        if (to.count(mode)) s.test.push_back(i);
    }
    return s;
}

/// What prices a frame: its ray cast per ray, or its update (ns); empty where nothing does.
using Price = std::function<double(const FrameObservation&)>;

/// One cell's frames priced: the ray cast by `ray`, and the frame (update + ray cast) where `update`
/// prices the update too; with an update price, a cell whose frames it cannot price gets no ray-cast
/// prediction either.
CellPrediction price_cell(const std::vector<const FrameObservation*>& fs, const Price& ray, const Price& update) {
    CellPrediction c;
    c.structure = fs.front()->structure, c.scene = fs.front()->scene, c.params = fs.front()->params;
    std::vector<double> frame, predicted_frame, raycast, predicted_raycast;
    for (const FrameObservation* f : fs) {
        frame.push_back(f->frame_ns());
        if (f->rays > 0) raycast.push_back(f->raycast_ns);
        if (!ray) continue;
        const double cast = f->rays > 0 ? f->rays * ray(*f) : 0.0;
        if (update) predicted_frame.push_back(update(*f) + cast);
        if (f->rays > 0) predicted_raycast.push_back(cast);
    }
    c.frame_ns = quantile(frame, 0.5);
    c.raycast_ns = quantile(raycast, 0.5);
    if (ray && update) c.predicted_frame_ns = quantile_or_nan(predicted_frame, 0.5);
    if (ray && (!update || c.predictable())) c.predicted_raycast_ns = quantile_or_nan(predicted_raycast, 0.5);
    c.frame_error = relative_error(c.predicted_frame_ns, c.frame_ns);
    c.raycast_error = relative_error(c.predicted_raycast_ns, c.raycast_ns);
    return c;
}

/// One cell's frames priced by `m`'s chosen models (null: no model).
CellPrediction predict_cell(const std::vector<const FrameObservation*>& fs, const StructureModels* m) {
    const bool model = m && m->predict_ray && m->predict_update;
    CellPrediction c = price_cell(fs, model ? m->predict_ray : Price(), model ? m->predict_update : Price());
    if (model) {
        c.raycast_model = m->chosen("raycast")->name;
        c.update_model = m->chosen("update")->name;
        c.outside = outside_trained_range(*m, fs);
    }
    return c;
}

/// One measured quantity of a cell, its prediction and its error.
struct Measure {
    double CellPrediction::*measured;
    double CellPrediction::*predicted;
    double CellPrediction::*error;
};

/// Median and p90 of one error over the cells, with the bootstrap over scenes: each resample
/// draws as many scenes as there are, with replacement, and pools their cells. A cell measured
/// but not priced (its structure had no model, or the model no column for it) is a miss, an
/// infinite error: it counts in the median and p90 as a cell beyond any bound, not left out. A
/// cell without the quantity (no rays) does not count.
ErrorSummary summarize_error(const std::vector<const CellPrediction*>& cells, Measure m,
                             const BootstrapOptions& options, std::uint64_t stream) {
    std::map<std::string, std::vector<double>> by_scene;
    std::vector<double> all;
    for (const CellPrediction* c : cells) {
        const bool miss = c->*m.measured > 0 && !std::isfinite(c->*m.predicted);
        const double e = miss ? INFINITY : c->*m.error;
        if (std::isnan(e)) continue;
        by_scene[c->scene].push_back(e);
        all.push_back(e);
    }
    ErrorSummary out;
    out.median = quantile(all, 0.5);
    out.p90 = quantile(all, 0.9);
    if (all.empty() || options.resamples <= 0) return out;
    std::vector<const std::vector<double>*> scenes;
    for (const auto& [scene, errors] : by_scene) scenes.push_back(&errors);
    Random rng(mix_seed(options.seed, stream));
    std::vector<double> medians, p90s, pooled;
    for (int r = 0; r < options.resamples; ++r) {
        pooled.clear();
        for (std::size_t k = 0; k < scenes.size(); ++k) {
            const std::vector<double>& drawn = *scenes[rng.below(scenes.size())];
            pooled.insert(pooled.end(), drawn.begin(), drawn.end());
        }
        medians.push_back(quantile(pooled, 0.5));
        p90s.push_back(quantile(pooled, 0.9));
    }
    out.median_low = quantile(medians, 0.025), out.median_high = quantile(medians, 0.975);
    out.p90_low = quantile(p90s, 0.025), out.p90_high = quantile(p90s, 0.975);
    return out;
}

nlohmann::json number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

/// A summary's figure: its value, "miss" where it falls on the misses, null where there is none.
nlohmann::json error_number(double v) { return std::isinf(v) ? nlohmann::json("miss") : number(v); }

nlohmann::json error_json(const ErrorSummary& e) {
    return {{"median", error_number(e.median)},
            {"median_ci95", {error_number(e.median_low), error_number(e.median_high)}},
            {"p90", error_number(e.p90)},
            {"p90_ci95", {error_number(e.p90_low), error_number(e.p90_high)}}};
}

}  // namespace

double relative_error(double predicted, double measured) {
    return std::isfinite(predicted) && measured > 0 ? std::abs(predicted - measured) / measured : NAN;
}

std::vector<ValidationSplit> family_out_splits(const std::vector<FrameObservation>& frames) {
    std::map<std::string, std::string> family;  // per scene, worked out once
    return leave_each_out(frames, kFamilyOutGroup, [&](const FrameObservation& f) {
        auto [it, fresh] = family.try_emplace(f.scene);
        if (fresh) it->second = scene_family(f.scene);
        return it->second;
    });
}

std::vector<ValidationSplit> generator_out_splits(const std::vector<FrameObservation>& frames) {
    return leave_each_out(frames, "leave-one-generator-out", [](const FrameObservation& f) { return f.category; });
}

std::vector<ValidationSplit> largest_out_splits(const std::vector<FrameObservation>& frames) {
    std::map<std::string, double> objects;  // per scene, its most objects in any frame
    for (const FrameObservation& f : frames) objects[f.scene] = std::max(objects[f.scene], f.objects);
    double most = 0;
    for (const auto& [scene, n] : objects) most = std::max(most, n);
    // The largest scenes' families leave together: a map's brushes and triangles differ in count.
    std::set<std::string> largest, families;
    for (const auto& [scene, n] : objects)
        if (n == most) families.insert(scene_family(scene));
    for (const auto& [scene, n] : objects)
        if (families.count(scene_family(scene))) largest.insert(scene);
    if (largest.size() == objects.size()) return {};
    ValidationSplit s{"leave-the-largest-out", "", {}, {}};
    for (const std::string& scene : largest) s.name += (s.name.empty() ? "" : "+") + scene;
    s.name += " (" + std::to_string(std::int64_t(most)) + " objects)";
    for (std::size_t i = 0; i < frames.size(); ++i) (largest.count(frames[i].scene) ? s.test : s.train).push_back(i);
    return {s};
}

std::vector<ValidationSplit> ray_mode_splits(const std::vector<FrameObservation>& frames) {
    std::set<std::string> modes;
    for (const FrameObservation& f : frames) modes.insert(ray_mode_of(f));
    std::vector<ValidationSplit> out;
    if (modes.size() < 2) return out;
    for (const std::string& mode : modes) {
        std::set<std::string> others = modes;
        others.erase(mode);
        out.push_back(transfer_split(frames, {mode}, others));
        // With two modes "the others -> this one" is the other mode's "this one -> the others".
        if (modes.size() > 2) out.push_back(transfer_split(frames, others, {mode}));
    }
    return out;
}

std::vector<ValidationSplit> nested_splits(const std::vector<FrameObservation>& frames) {
    std::vector<ValidationSplit> out;
    for (const auto& make : {family_out_splits, generator_out_splits, largest_out_splits, ray_mode_splits}) {
        std::vector<ValidationSplit> more = make(frames);
        out.insert(out.end(), std::make_move_iterator(more.begin()), std::make_move_iterator(more.end()));
    }
    return out;
}

std::vector<CellPrediction> predict_cells(const std::vector<StructureModels>& models,
                                          const std::vector<const FrameObservation*>& frames,
                                          const std::string& split) {
    std::map<std::string, const StructureModels*> by_structure;
    for (const StructureModels& m : models) by_structure[m.structure] = &m;
    std::map<std::pair<std::string, int>, std::vector<const FrameObservation*>> cells;
    for (const FrameObservation* f : frames) cells[{f->structure, f->config_group}].push_back(f);
    std::vector<CellPrediction> out;
    for (const auto& [key, fs] : cells) {
        const auto it = by_structure.find(key.first);
        out.push_back(predict_cell(fs, it == by_structure.end() ? nullptr : it->second));
        out.back().split = split;
    }
    return out;
}

std::vector<CellPrediction> run_split(const std::vector<FrameObservation>& frames, const ValidationSplit& split,
                                      const ModelInputs& inputs) {
    std::vector<FrameObservation> train;
    for (std::size_t i : split.train) train.push_back(frames[i]);
    std::vector<const FrameObservation*> test;
    for (std::size_t i : split.test) test.push_back(&frames[i]);
    return predict_cells(fit_cost_models(train, inputs), test, split.name);
}

std::vector<StructureValidation> summarize(const std::vector<CellPrediction>& cells, const BootstrapOptions& options,
                                           bool frames_priced) {
    std::map<std::string, std::vector<const CellPrediction*>> by_structure;
    for (const CellPrediction& c : cells) by_structure[c.structure].push_back(&c);
    std::vector<StructureValidation> out;
    std::uint64_t stream = 0;
    for (const auto& [structure, cs] : by_structure) {
        StructureValidation v;
        v.structure = structure;
        v.cells = cs.size();
        std::set<std::string> scenes, splits;
        for (const CellPrediction* c : cs) {
            if (!c->predictable()) ++v.unpredictable;
            if (!c->predictable()) continue;
            v.outside += !c->outside.empty();
            scenes.insert(c->scene);
            if (!splits.insert(c->split).second) continue;  // forms counted once per split
            ++v.raycast_models[c->raycast_model];
            ++v.update_models[c->update_model];
        }
        v.scenes = scenes.size();
        for (const CellPrediction* c : cs)
            v.misses += !c->predictable() ||
                        (frames_priced && c->frame_ns > 0 && !std::isfinite(c->predicted_frame_ns)) ||
                        (c->raycast_ns > 0 && !std::isfinite(c->predicted_raycast_ns));
        if (frames_priced)
            v.frame = summarize_error(
                cs, {&CellPrediction::frame_ns, &CellPrediction::predicted_frame_ns, &CellPrediction::frame_error},
                options, stream);
        ++stream;
        v.raycast = summarize_error(
            cs, {&CellPrediction::raycast_ns, &CellPrediction::predicted_raycast_ns, &CellPrediction::raycast_error},
            options, stream++);
        out.push_back(std::move(v));
    }
    return out;
}

std::vector<ValidationGroup> validate_nested(const std::vector<FrameObservation>& frames, const ModelInputs& inputs,
                                             const std::vector<ValidationSplit>& splits,
                                             const BootstrapOptions& options) {
    std::vector<ValidationGroup> out;
    for (const ValidationSplit& split : splits) {
        auto g = std::find_if(out.begin(), out.end(), [&](const ValidationGroup& x) { return x.name == split.group; });
        if (g == out.end()) g = out.insert(out.end(), ValidationGroup{split.group, {}, {}, {}});
        g->splits.push_back(split.name);
        std::vector<CellPrediction> cells = run_split(frames, split, inputs);
        g->cells.insert(g->cells.end(), cells.begin(), cells.end());
    }
    for (ValidationGroup& g : out) g.structures = summarize(g.cells, options);
    return out;
}

TransferValidation validate_transfer(const std::vector<StructureModels>& models,
                                     const std::vector<FrameObservation>& test, const BootstrapOptions& options) {
    std::vector<const FrameObservation*> frames;
    for (const FrameObservation& f : test) frames.push_back(&f);
    TransferValidation out;
    out.group.name = kTransferGroup;
    out.group.splits = {kTransferGroup};
    out.group.cells = predict_cells(models, frames, kTransferGroup);
    std::set<std::string> modelled, unpredictable;
    for (const StructureModels& m : models)
        if (m.predict_ray && m.predict_update) modelled.insert(m.structure);
    for (const FrameObservation& f : test)
        if (!modelled.count(f.structure)) unpredictable.insert(f.structure);
    out.unpredictable.assign(unpredictable.begin(), unpredictable.end());
    out.group.structures = summarize(out.group.cells, options);
    return out;
}

ValidationGroup validate_calibration_only(const std::vector<FrameObservation>& frames, const ModelInputs& inputs,
                                          const BootstrapOptions& options) {
    ValidationGroup g{kCalibrationGroup, {kCalibrationGroup}, {}, {}};
    std::map<std::pair<std::string, int>, std::vector<const FrameObservation*>> cells;
    for (const FrameObservation& f : frames) cells[{f.structure, f.config_group}].push_back(&f);
    for (const auto& [key, fs] : cells) {
        const std::string& structure = key.first;  // clang 14 cannot capture a structured binding
        const auto cal = std::find_if(inputs.calibrations.begin(), inputs.calibrations.end(),
                                      [&](const StructureCalibration& c) { return c.structure == structure; });
        // ns per ray from the calibrated terms (the table's terms with a prior, each times its
        // counter, a constant times 1); NaN when the micro-scenes fitted none.
        const auto per_ray = [&](const FrameObservation& f) {
            if (cal == inputs.calibrations.end()) return double(NAN);
            double ns = 0;
            bool any = false;
            for (const CostTerm& term : cost_terms()) {
                if (!term.prior) continue;
                const CalibratedTerm* t = cal->term(term.name);
                if (!t || !std::isfinite(t->value)) continue;
                double count = term.counters.empty() ? 1.0 : 0.0;
                for (const char* symbol : term.counters) count += f.*find_counter(symbol).field;
                ns += t->value * count, any = true;
            }
            return any ? ns : double(NAN);
        };
        CellPrediction c = price_cell(fs, per_ray, {});
        c.split = kCalibrationGroup;
        c.raycast_model = "calibration";
        g.cells.push_back(std::move(c));
    }
    g.structures = summarize(g.cells, options, false);
    return g;
}

std::map<std::pair<std::string, std::string>, double> scene_frame_errors(const std::vector<CellPrediction>& cells) {
    std::map<std::pair<std::string, std::string>, std::pair<double, int>> sums;
    for (const CellPrediction& c : cells)
        if (std::isfinite(c.frame_error)) {
            auto& [sum, n] = sums[{c.structure, c.scene}];
            sum += c.frame_error, ++n;
        }
    std::map<std::pair<std::string, std::string>, double> out;
    for (const auto& [key, s] : sums) out[key] = s.first / s.second;
    return out;
}

std::string run_uuid(Database& db, std::int64_t run) {
    const std::optional<StoredRun> info = read_stored_run(db, run);
    return info ? info->uuid : "";
}

void store_validation(Database& db, std::int64_t run, const std::string& train, const std::string& train_uuid,
                      const ValidationGroup& group, const BootstrapOptions& options) {
    const auto value = [](double v) { return std::isfinite(v) ? std::optional<double>(v) : std::nullopt; };
    std::vector<StoredValidation> rows;
    for (const StructureValidation& s : group.structures) {
        StoredValidation r{s.structure,
                           std::int64_t(s.cells),
                           std::int64_t(s.unpredictable),
                           std::int64_t(s.scenes),
                           std::int64_t(s.outside),
                           {},
                           nlohmann::json{{"raycast", s.raycast_models}, {"update", s.update_models}}.dump()};
        for (const ErrorSummary* e : {&s.frame, &s.raycast})
            for (double v : {e->median, e->median_low, e->median_high, e->p90, e->p90_low, e->p90_high})
                r.errors.push_back(value(v));
        rows.push_back(std::move(r));
    }
    write_validation(db,
                     {run, train, train_uuid, group.name, nlohmann::json(group.splits).dump(),
                      std::int64_t(options.resamples), std::int64_t(options.seed)},
                     rows);
}

nlohmann::json validation_json(const ValidationGroup& group, bool with_cells) {
    nlohmann::json j{{"group", group.name}, {"splits", group.splits}, {"structures", nlohmann::json::array()}};
    for (const StructureValidation& s : group.structures)
        j["structures"].push_back({{"structure", s.structure},
                                   {"cells", s.cells},
                                   {"unpredictable_cells", s.unpredictable},
                                   {"miss_cells", s.misses},
                                   {"outside_range_cells", s.outside},
                                   {"scenes", s.scenes},
                                   {"frame_error", error_json(s.frame)},
                                   {"raycast_error", error_json(s.raycast)},
                                   {"raycast_models", s.raycast_models},
                                   {"update_models", s.update_models}});
    if (!with_cells) return j;
    j["cells"] = nlohmann::json::array();
    for (const CellPrediction& c : group.cells)
        j["cells"].push_back({{"split", c.split},
                              {"structure", c.structure},
                              {"scene", c.scene},
                              {"params", c.params},
                              {"raycast_model", c.raycast_model},
                              {"update_model", c.update_model},
                              {"frame_ns", number(c.frame_ns)},
                              {"predicted_frame_ns", number(c.predicted_frame_ns)},
                              {"raycast_ns", number(c.raycast_ns)},
                              {"predicted_raycast_ns", number(c.predicted_raycast_ns)},
                              {"frame_error", number(c.frame_error)},
                              {"raycast_error", number(c.raycast_error)},
                              {"outside", c.outside.empty() ? nlohmann::json(nullptr) : nlohmann::json(c.outside)}});
    return j;
}

}  // namespace rcb
