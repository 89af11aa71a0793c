#include "tuner/tuning.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <set>

#include "analysis/cost_model.h"
#include "core/base/error.h"
#include "core/base/number_text.h"
#include "core/base/random.h"
#include "accel/registry.h"
#include "accel/narrow/narrow_phase.h"
#include "sim/simulator.h"
#include "runner/calibration.h"
#include "runner/repetition_plan.h"
#include "tuner/search_baselines.h"

namespace rcb {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;
using Clock = std::chrono::steady_clock;

/// The measured search's cost of a configuration that fails the accuracy constraint (× its time).
constexpr double kInaccuratePenalty = 1e6;

}  // namespace

const Recording& recording_of(const SceneSpec& scene) {
    static std::map<std::string, Recording> cache;
    const std::string key = scene.key.dump() + "|" + scene.path;
    auto it = cache.find(key);
    if (it == cache.end()) it = cache.emplace(key, load_scene(scene)).first;
    return it->second;
}

namespace {

json complete(const std::string& structure, const json& searched) {
    const StructureInfo& info = find_structure(structure);
    json p = info.defaults();
    for (const auto& [k, v] : searched.items()) p[k] = v;
    // One spelling per configuration: a real parameter given as 4 is the default 4.0, not a second
    // candidate measured again.
    for (const ParamSpec& spec : info.params)
        if (spec.kind == ParamKind::real && p[spec.name].is_number()) p[spec.name] = p[spec.name].get<double>();
    return p;
}

/// Frames of one measured run as cost-model observations.
void add_observations(const SimulationResult& r, const std::string& scene, const std::string& category, int group,
                      std::vector<FrameObservation>& out) {
    for (const FrameResult& f : r.frames) {
        if (f.warmup || f.rays == 0) continue;
        FrameObservation o = observation_of(f, double(r.objects));
        o.structure = r.structure;
        o.params = r.params.dump();
        o.scene = scene;
        o.category = category;
        o.config_group = group;
        out.push_back(o);
    }
}

std::atomic<std::uint64_t> timed_simulations{0}, counting_simulations{0}, counting_update_timed{0};

std::vector<SimulationResult> run_simulations(const TuneCategory& category, const std::string& structure,
                                              const json& params, const SimulationOptions& options,
                                              std::uint32_t repetitions) {
    SimulationOptions o = options;
    if (category.timing) o.count = true;  // made-up times are priced from the counters
    std::vector<SimulationResult> out;
    for (const PlannedRun& p : repetition_plan(category.scenes.size(), repetitions, std::nullopt)) {
        out.push_back(simulate(recording_of(category.scenes[p.item]), find_structure(structure), params, o));
        if (category.timing) category.timing(out.back());
        ++(options.timed_cast ? timed_simulations : counting_simulations);
        if (!options.timed_cast && options.timed_update) ++counting_update_timed;
    }
    return out;
}

MeasuredCost summarise(const std::vector<SimulationResult>& runs, std::size_t scenes) {
    // Per scene: median and MAD of frame totals over frames × repetitions; then the mean over scenes.
    MeasuredCost c;
    for (std::size_t s = 0; s < scenes; ++s) {
        std::vector<double> total, update, cast;
        double memory = 0;
        int n = 0;
        for (std::size_t i = s; i < runs.size(); i += scenes) {
            for (const FrameResult& f : runs[i].frames) {
                if (f.warmup) continue;
                total.push_back((double(f.update_ns) + double(f.raycast_ns)) / 1e6);
                update.push_back(double(f.update_ns) / 1e6);
                cast.push_back(double(f.raycast_ns) / 1e6);
            }
            memory += double(runs[i].memory_bytes), ++n;
        }
        const Spread t = spread_of(total);
        c.ms += t.median / double(scenes);
        c.mad += t.mad / double(scenes);
        c.update_ms += spread_of(update).median / double(scenes);
        c.raycast_ms += spread_of(cast).median / double(scenes);
        c.memory_bytes += (n ? memory / n : 0) / double(scenes);
    }
    return c;
}

std::string category_of(const SceneSpec& s) {
    if (s.source == SceneSpec::Source::import) return "import";
    if (s.source == SceneSpec::Source::recording) return "recording";
    return s.settings.generator;
}

std::vector<json> levels_for(const ParamSpec& p) {
    std::vector<json> out;
    switch (p.kind) {
        case ParamKind::boolean:
            return {false, true};
        case ParamKind::choice:
            for (const std::string& c : p.choices) out.push_back(c);
            return out;
        case ParamKind::integer: {
            const long lo = std::lround(p.lo), hi = std::lround(p.hi);
            if (hi - lo + 1 <= 12) {
                for (long v = lo; v <= hi; ++v) out.push_back(v);
            } else {
                for (long v = std::max(1L, lo); v <= hi; v *= 2) out.push_back(v);
                if (lo < 1) out.insert(out.begin(), json(lo));
            }
            return out;
        }
        case ParamKind::real:
            // As a range's levels (runner/experiment.h, expand_values): the decimals they stand for.
            if (p.log_scale && p.lo > 0) {
                for (double v = p.lo; v <= p.hi * (1 + 1e-9); v *= 2)
                    out.push_back(std::clamp(decimal_rounded(v), p.lo, p.hi));
            } else {
                for (int i = 0; i < 8; ++i)
                    out.push_back(std::clamp(decimal_rounded(p.lo + (p.hi - p.lo) * i / 7.0), p.lo, p.hi));
            }
            return out;
    }
    return out;
}

}  // namespace

SimulationTally simulation_tally() {
    return {timed_simulations.load(), counting_simulations.load(), counting_update_timed.load()};
}

std::size_t simplest_within(const std::vector<const Candidate*>& all, double tolerance) {
    double fastest = INFINITY;
    for (const Candidate* c : all) fastest = std::min(fastest, c->measured->ms);
    std::size_t best = SIZE_MAX;
    auto simpler = [](const Candidate* a, const Candidate* b) {
        const int sa = structure_simplicity(a->structure), sb = structure_simplicity(b->structure);
        if (sa != sb) return sa < sb;
        if (a->measured->memory_bytes != b->measured->memory_bytes)
            return a->measured->memory_bytes < b->measured->memory_bytes;
        return a->measured->ms < b->measured->ms;
    };
    for (std::size_t i = 0; i < all.size(); ++i)
        if (all[i]->measured->ms <= (1 + tolerance) * fastest && (best == SIZE_MAX || simpler(all[i], all[best])))
            best = i;
    return best;
}

int structure_simplicity(const std::string& structure) {
    const StructureInfo* info = registered_structure(structure);
    return info ? info->simplicity : StructureInfo{}.simplicity;
}

std::vector<SearchDimension> default_space(const std::string& structure) {
    std::vector<SearchDimension> dims;
    for (const ParamSpec& p : find_structure(structure).params)
        if (p.tunable) dims.push_back({p.name, levels_for(p)});
    return dims;
}

namespace {

/// Whether the scene entry at `where` (a path ending in "[i]") in `scenes` gives its own rays.
bool scene_sets_rays(const json& scenes, const std::string& where) {
    const std::size_t open = where.rfind('[');
    if (open == std::string::npos) return false;
    const std::size_t i = std::stoul(where.substr(open + 1));
    return i < scenes.size() && scenes[i].is_object() && scenes[i].contains("rays_per_frame");
}

/// A recording's frames and rays are known once it is read (here, into the cache the tuning
/// measures from): warm-up must leave a frame, and the measured frames must cast rays.
void check_tuned_recording(const SceneSpec& s, std::uint32_t warmup, const std::string& category) {
    const Recording& r = recording_of(s);
    const std::string scene = "scene " + s.name + " (" + s.path + ") of category " + category;
    if (warmup >= r.frames.size())
        fail("warmup_frames", std::to_string(warmup) + " warm-up frames leave none of the " +
                                  std::to_string(r.frames.size()) + " frames of " + scene);
    std::size_t rays = 0;
    for (std::size_t f = warmup; f < r.frames.size(); ++f) rays += r.frames[f].rays.size();
    if (rays == 0)
        fail(at(s.where, "recording"),
             "no rays in the measured frames of " + scene + ": a tuning fits its cost model per ray cast");
}

/// Thins the registry's levels of the parameters the file left out until a structure's space has
/// at most kMaxPlanCells configurations (the exhaustive check and the predicted mode's calibration
/// enumerate it): the widest such dimension keeps every other level, and its first, last and
/// default levels. Levels the file gave stay as given; a space still too large is refused below.
void fit_default_levels(const std::string& structure, std::vector<SearchDimension>& dims,
                        const std::set<std::string>& given) {
    auto size = [&] {
        double n = 1;
        for (const SearchDimension& d : dims) n *= double(std::max<std::size_t>(1, d.levels.size()));
        return n;
    };
    const json defaults = find_structure(structure).defaults();
    std::set<std::string> stuck = given;
    while (size() > double(kMaxPlanCells)) {
        SearchDimension* widest = nullptr;
        for (SearchDimension& d : dims)
            if (!stuck.count(d.name) && d.levels.size() > 3 && (!widest || d.levels.size() > widest->levels.size()))
                widest = &d;
        if (!widest) return;
        std::vector<json> kept;
        for (std::size_t i = 0; i < widest->levels.size(); ++i)
            if (i % 2 == 0 || i + 1 == widest->levels.size() ||
                widest->levels[i] == defaults.value(widest->name, json()))
                kept.push_back(widest->levels[i]);
        if (kept.size() == widest->levels.size()) stuck.insert(widest->name);
        widest->levels = std::move(kept);
    }
}

/// The search space of every tuned structure: the registry's default levels, the file's "space"
/// over them, and default levels thinned to fit the limit.
void parse_space(const json& j, TuneSpec& t) {
    for (const std::string& s : t.structures) {
        t.space[s] = default_space(s);
        if (t.space[s].empty()) fail("structures", s + " has no tunable parameter");
    }
    std::map<std::string, std::set<std::string>> given;
    if (j.contains("space")) {
        expect_object(j["space"], "space");
        for (const auto& [structure, params] : j["space"].items()) {
            const std::string path = at("space", structure);
            if (std::find(t.structures.begin(), t.structures.end(), structure) == t.structures.end())
                fail(path, "not one of the structures tuned here");
            expect_object(params, path);
            const StructureInfo& info = find_structure(structure);
            for (const auto& [param, value] : params.items()) {
                auto spec = std::find_if(info.params.begin(), info.params.end(),
                                         [&, &param = param](const ParamSpec& p) { return p.name == param; });
                if (spec == info.params.end())
                    check_params(info.params, json{{param, value}}, path, structure);  // throws
                auto& dims = t.space[structure];
                auto dim = std::find_if(dims.begin(), dims.end(),
                                        [&, &param = param](const SearchDimension& d) { return d.name == param; });
                std::vector<json> levels = expand_values(*spec, value, at(path, param));
                if (dim == dims.end())
                    dims.push_back({param, levels});  // a non-tunable parameter the user wants searched
                else
                    dim->levels = levels;
                given[structure].insert(param);
            }
        }
    }
    // The exhaustive check and the predicted mode's calibration enumerate a space: refuse one
    // too large to hold before anything is allocated.
    for (auto& [structure, dims] : t.space) {
        fit_default_levels(structure, dims, given[structure]);
        double size = 1;
        for (const SearchDimension& dim : dims) size *= double(std::max<std::size_t>(1, dim.levels.size()));
        if (size > double(kMaxPlanCells))
            fail(at("space", structure), "the search space has " + std::to_string(std::uint64_t(std::min(size, 1e19))) +
                                             " configurations, more than the limit of " +
                                             std::to_string(kMaxPlanCells) + "; give fewer levels");
    }
}

}  // namespace

TuneSpec parse_tune_spec(const std::string& text, const std::string& name, const std::string& base_dir) {
    const json j = parse_json_document(text, name);
    try {
        expect_object(j, "(top level)");
        check_keys(j, "",
                   {"name", "description", "mode", "structures", "space", "budget", "calibration", "verify_top", "seed",
                    "frames", "warmup_frames", "rays_per_frame", "ray_mix", "repetitions", "categories"});
        TuneSpec t;
        t.content = text;
        t.name = get_string(j, "name", "", fs::path(name).stem().string());
        t.description = get_string(j, "description", "", "");
        t.mode = get_string(j, "mode", "", t.mode);
        if (t.mode != "measured" && t.mode != "predicted" && t.mode != "predicted-then-verified")
            fail("mode", "expected one of measured, predicted, predicted-then-verified, got \"" + t.mode + "\"");
        t.budget = get_uint(j, "budget", "", 1, 100000, t.budget);
        t.calibration = get_uint(j, "calibration", "", 3, 1000, t.calibration);
        t.verify_top = get_uint(j, "verify_top", "", 1, 100, t.verify_top);
        t.seed = get_uint(j, "seed", "", 0, UINT64_MAX, t.seed);
        t.warmup_frames = std::uint32_t(get_uint(j, "warmup_frames", "", 0, 1000, t.warmup_frames));
        t.repetitions = std::uint32_t(get_uint(j, "repetitions", "", 1, 1000, t.repetitions));
        SceneDefaults d;
        d.frames = std::uint32_t(get_uint(j, "frames", "", 1, 1'000'000, 6));
        d.rays = std::uint32_t(get_uint(j, "rays_per_frame", "", 0, 100'000'000, d.rays));
        d.ray_mix = get_string(j, "ray_mix", "", d.ray_mix);

        if (j.contains("structures")) {
            if (!j["structures"].is_array() || j["structures"].empty())
                fail("structures", "expected a non-empty list of structure names");
            for (std::size_t i = 0; i < j["structures"].size(); ++i) {
                const json& s = j["structures"][i];
                if (!s.is_string()) fail(at("structures", i), "expected a structure name, got " + json_excerpt(s));
                try {
                    t.structures.push_back(find_structure(s.get<std::string>()).name);
                } catch (const InputError& e) {
                    fail(at("structures", i), e.what());
                }
            }
        } else {
            for (const StructureInfo& info : structure_registry())
                if (std::any_of(info.params.begin(), info.params.end(), [](const ParamSpec& p) { return p.tunable; }))
                    t.structures.push_back(info.name);
        }
        parse_space(j, t);
        if (!j.contains("categories") || !j["categories"].is_array() || j["categories"].empty())
            fail("categories", "expected a non-empty list of scene categories");
        std::set<std::string> names;
        for (std::size_t i = 0; i < j["categories"].size(); ++i) {
            const json& c = j["categories"][i];
            const std::string path = at("categories", i);
            expect_object(c, path);
            check_keys(c, path, {"name", "scenes"});
            TuneCategory cat;
            cat.name = get_string(c, "name", path, "");
            if (cat.name.empty()) fail(at(path, "name"), "a category needs a name");
            if (!names.insert(cat.name).second) fail(at(path, "name"), "duplicate category name \"" + cat.name + "\"");
            if (!c.contains("scenes")) fail(at(path, "scenes"), "expected a non-empty list of scenes");
            cat.scenes = parse_scenes(c["scenes"], at(path, "scenes"), d, base_dir);
            for (const SceneSpec& s : cat.scenes) {
                if (s.source != SceneSpec::Source::recording && t.warmup_frames >= s.settings.frames)
                    fail("warmup_frames", "leaves no measured frame in category " + cat.name);
                if (s.source == SceneSpec::Source::recording) check_tuned_recording(s, t.warmup_frames, cat.name);
                // Every tuning fits eq. 5.4 per ray: a scene without rays leaves nothing to fit.
                if (s.source != SceneSpec::Source::recording && s.settings.rays.per_frame == 0)
                    fail(scene_sets_rays(c["scenes"], s.where) ? at(s.where, "rays_per_frame") : "rays_per_frame",
                         "0 rays per frame in scene " + s.name + " of category " + cat.name +
                             ": a tuning fits its cost model per ray cast, so it needs rays");
            }
            t.categories.push_back(std::move(cat));
        }
        return t;
    } catch (const InputError& e) {
        throw InputError(name + ": " + e.what());
    }
}

TuneSpec load_tune_spec(const std::string& path) {
    if (fs::is_directory(path)) throw InputError(path + ": is a directory, not a tuning file");
    return parse_tune_spec(read_text_file(path), path, fs::path(path).parent_path().string());
}

namespace {

SimulationOptions measuring_options(std::uint32_t warmup_frames) {
    SimulationOptions o;
    o.verify = false;  // correctness is the tests' job; tuning measures speed
    o.count = false;
    o.warmup_frames = warmup_frames;
    return o;
}

/// One repetition of a configuration on every scene of the category; `verify` also checks it
/// against the ground truth (untimed): the accuracy a constraint judges.
std::vector<SimulationResult> one_repetition(const TuneCategory& category, const std::string& structure,
                                             const json& params, std::uint32_t warmup_frames, bool verify) {
    SimulationOptions o = measuring_options(warmup_frames);
    o.verify = verify;
    return run_simulations(category, structure, params, o, 1);
}

/// `repetitions` of every configuration of `params` in the planner's order (runner/repetition_plan.h:
/// repetition-major, the configurations in their order, as advise's too); the first verified when
/// `verify`.
std::vector<std::vector<SimulationResult>> repeated_runs(const TuneCategory& category, const std::string& structure,
                                                         const std::vector<json>& params, std::uint32_t warmup_frames,
                                                         std::uint32_t repetitions, bool verify) {
    std::vector<std::vector<SimulationResult>> runs(params.size());
    for (const PlannedRun& p : repetition_plan(params.size(), repetitions, std::nullopt)) {
        std::vector<SimulationResult> r =
            one_repetition(category, structure, params[p.item], warmup_frames, verify && p.repetition == 0);
        runs[p.item].insert(runs[p.item].end(), std::make_move_iterator(r.begin()), std::make_move_iterator(r.end()));
    }
    return runs;
}

/// The cost of measured runs, repetition-major (the first repetition's runs first, verified when
/// `verify`).
MeasuredCost cost_of(const std::vector<SimulationResult>& runs, const TuneCategory& category,
                     const std::string& structure, const json& params, bool verify) {
    MeasuredCost c = summarise(runs, category.scenes.size());
    c.accuracy.exact_level = query_level_of(complete(structure, params)) != QueryLevel::candidates;
    if (verify) {
        c.accuracy.verified = true;
        for (std::size_t s = 0; s < category.scenes.size(); ++s) {
            std::uint64_t returned = 0, correct = 0, relevant = 0;
            for (const FrameResult& f : runs[s].frames) {
                c.accuracy.mismatches += f.mismatches();
                if (f.warmup) continue;
                returned += f.returned, correct += f.correct, relevant += f.relevant;
            }
            c.accuracy.precision = std::min(c.accuracy.precision, returned ? double(correct) / double(returned) : 1.0);
            c.accuracy.recall = std::min(c.accuracy.recall, relevant ? double(correct) / double(relevant) : 1.0);
        }
    }
    return c;
}

/// The first repetition of measured `runs` (the first of each scene) as cost-model observations.
/// The counters come from a replay of their own (deterministic, so frame for frame those of the
/// timed run): counting between the timed frames would slow them by a few percent.
void observe(const TuneCategory& category, const std::string& structure, const json& params,
             std::uint32_t warmup_frames, const std::vector<SimulationResult>& runs, int group,
             std::vector<FrameObservation>& out) {
    SimulationOptions replay = measuring_options(warmup_frames);
    replay.timed_cast = false;
    replay.count = true;
    const std::vector<SimulationResult> counted = run_simulations(category, structure, params, replay, 1);
    for (std::size_t s = 0; s < category.scenes.size(); ++s) {
        SimulationResult timed = runs[s];
        for (std::size_t f = 0; f < timed.frames.size() && f < counted[s].frames.size(); ++f)
            timed.frames[f].counters = counted[s].frames[f].counters;
        add_observations(timed, category.scenes[s].name, category_of(category.scenes[s]), group * 100 + int(s), out);
    }
}

}  // namespace

MeasuredCost measure(const TuneCategory& category, const std::string& structure, const json& params,
                     std::uint32_t warmup_frames, std::uint32_t repetitions, bool verify,
                     std::vector<FrameObservation>* observations, int group) {
    const std::vector<SimulationResult> runs = std::move(
        repeated_runs(category, structure, std::vector<json>{params}, warmup_frames, repetitions, verify).front());
    if (observations) observe(category, structure, params, warmup_frames, runs, group, *observations);
    return cost_of(runs, category, structure, params, verify);
}

std::vector<MeasuredCost> measure_interleaved(const TuneCategory& category, const std::string& structure,
                                              const std::vector<json>& params, std::uint32_t warmup_frames,
                                              std::uint32_t repetitions, bool verify,
                                              std::vector<std::vector<FrameObservation>>* observations) {
    const std::vector<std::vector<SimulationResult>> runs =
        repeated_runs(category, structure, params, warmup_frames, repetitions, verify);
    std::vector<MeasuredCost> out;
    if (observations) observations->assign(params.size(), {});
    for (std::size_t i = 0; i < params.size(); ++i) {
        out.push_back(cost_of(runs[i], category, structure, params[i], verify));
        if (observations) observe(category, structure, params[i], warmup_frames, runs[i], int(i), (*observations)[i]);
    }
    return out;
}

double constrained_cost(const MeasuredCost& cost, const AccuracyConstraint& accuracy) {
    return accuracy.met_by(cost.accuracy) ? cost.ms : kInaccuratePenalty * (1 + cost.ms);
}

void set_accuracy(TuneSpec& spec, const AccuracyConstraint& accuracy) {
    spec.accuracy = accuracy;
    if (!accuracy.allows_inexact()) return;
    const ParamSpec query = query_param_spec();
    for (const std::string& structure : spec.structures) {
        std::vector<SearchDimension>& dims = spec.space[structure];
        if (std::none_of(dims.begin(), dims.end(), [&](const SearchDimension& d) { return d.name == query.name; }))
            dims.push_back({query.name, levels_for(query)});
    }
}

std::vector<const Candidate*> meeting(const std::vector<const Candidate*>& all, const AccuracyConstraint& accuracy) {
    std::vector<const Candidate*> out;
    for (const Candidate* c : all)
        if (accuracy.met_by(c->measured->accuracy)) out.push_back(c);
    return out;
}

namespace {

std::optional<CostCoefficients> chosen_coefficients(const std::vector<StructureModels>& models) {
    const CandidateModel* model = models.empty() ? nullptr : models.front().chosen("raycast");
    if (!model) return std::nullopt;
    // A per-category model (a tuning category of several scene generators): the first category's terms.
    CostCoefficients c = CostCoefficients::from_fit(model->fit.coefficients, "");
    c.model = model->name + " (held-out error " + std::to_string(int(std::lround(100 * model->heldout_error))) + "%, " +
              model->fit.status() + ")";
    return c;
}

/// Whether `c` prices any of the traversal's work (cost_terms(): `traversal`).
bool prices_ray_work(const CostCoefficients& c) {
    for (const CostTerm* t : tuning_terms())
        if (t->traversal && c[t->name] > 0) return true;
    return false;
}

/// The machine's micro-scene costs as a model: each tuning term the calibration fitted above 0.
CostCoefficients calibration_alone(const StructureCalibration& calibration) {
    CostCoefficients c;
    for (const CostTerm* t : tuning_terms())
        if (const CalibratedTerm* k = calibration.term(t->name); k && k->value > 0) c[t->name] = k->value;
    c.model = "the micro-scene calibration alone (the fit priced no ray work, with or without its priors)";
    return c;
}

}  // namespace

std::optional<CostCoefficients> fit_coefficients(const std::vector<FrameObservation>& frames,
                                                 const std::function<const ModelInputs&()>& priors,
                                                 std::optional<UpdatePrices>* update) {
    const std::vector<StructureModels> models = fit_cost_models(frames);
    // The update's fit takes no priors (cost_model.h): this fit's is the one.
    if (update) *update = models.empty() ? std::nullopt : update_prices(models.front());
    std::optional<CostCoefficients> c = chosen_coefficients(models);
    if (!c || prices_ray_work(*c) || !priors || priors().calibrations.empty()) return c;
    // A few noisy points can hide the rays' work; a model that prices none ranks configurations
    // by their memory alone. First the fit again, bounded by what the micro-scenes pinned.
    std::optional<CostCoefficients> bounded = chosen_coefficients(fit_cost_models(frames, priors()));
    if (bounded && prices_ray_work(*bounded)) {
        bounded->model += " with the calibration's priors (without them the fit priced no ray work)";
        return bounded;
    }
    // Then the micro-scenes' own costs, pinned or not (calibration alone, without the experiment).
    const CostCoefficients alone = calibration_alone(priors().calibrations.front());
    return prices_ray_work(alone) ? alone : c;
}

std::optional<CostCoefficients> prior_coefficients(MachinePriors* priors, const std::string& structure) {
    if (!priors || priors->of(structure).calibrations.empty()) return std::nullopt;
    CostCoefficients c = calibration_alone(priors->of(structure).calibrations.front());
    if (!prices_ray_work(c)) return std::nullopt;
    c.model = "the micro-scene calibration alone (nothing of the space timed)";
    return c;
}

double UpdatePrices::per_frame_ns(const FrameObservation& f) const {
    double ns = 0;
    for (const auto& [name, value] : terms) ns += value * term_value(find_term(name), f);
    return ns;
}

json UpdatePrices::to_json() const {
    json j = {{"model", model}, {"terms", json::object()}};
    for (const auto& [name, value] : terms) j["terms"][name] = value;
    return j;
}

namespace {

/// A term an UpdatePrices may carry: an update term of the table (a per-configuration column is not).
bool plain_update_term(const std::string& name) {
    const auto& all = cost_terms();
    const auto t = std::find_if(all.begin(), all.end(), [&](const CostTerm& c) { return c.name == name; });
    return t != all.end() && t->target == Target::update;
}

}  // namespace

UpdatePrices UpdatePrices::from_json(const json& j, const std::string& where) {
    if (!j.is_object() || !j.contains("terms") || !j["terms"].is_object())
        throw InputError(where + ".update_model: expected {\"model\": TEXT, \"terms\": {TERM: ns, …}}");
    UpdatePrices p;
    if (j.contains("model") && j["model"].is_string()) p.model = j["model"].get<std::string>();
    for (const auto& [name, value] : j["terms"].items()) {
        const std::string at = where + ".update_model.terms." + name;
        if (!plain_update_term(name)) throw InputError(at + ": not an update term of the cost model");
        if (!value.is_number() || !std::isfinite(value.get<double>()) || value.get<double>() < 0)
            throw InputError(at + ": expected a finite number >= 0, got " + json_excerpt(value));
        p.terms.emplace_back(name, value.get<double>());
    }
    return p;
}

std::optional<UpdatePrices> update_prices(const StructureModels& m) {
    const CandidateModel* best = nullptr;
    for (const CandidateModel& c : m.update) {
        if (c.fit.coefficients.empty() || !std::all_of(c.fit.coefficients.begin(), c.fit.coefficients.end(),
                                                       [](const Coefficient& k) { return plain_update_term(k.name); }))
            continue;
        // The chosen form where it is plain, else the plain form with the lowest held-out error.
        if (!best || (c.chosen && !best->chosen) || (!best->chosen && c.heldout_error < best->heldout_error)) best = &c;
    }
    if (!best) return std::nullopt;
    UpdatePrices p;
    for (const Coefficient& k : best->fit.coefficients) p.terms.emplace_back(k.name, k.value);
    p.model = best->name + " (held-out error " + std::to_string(int(std::lround(100 * best->heldout_error))) + "%" +
              (best->chosen ? "" : "; the chosen form is not plain") + ")";
    return p;
}

CountingReplay counting_replay(const TuneCategory& category, const std::string& structure, const json& searched,
                               std::uint32_t warmup_frames, const UpdatePrices* update) {
    SimulationOptions replay = untimed_replay(warmup_frames);
    replay.timed_update = update == nullptr;  // no prices: the update is timed, as it runs
    CountingReplay out;
    out.update_timed = replay.timed_update;
    for (const SimulationResult& r : run_simulations(category, structure, complete(structure, searched), replay, 1)) {
        std::vector<CountingReplay::Frame>& frames = out.scenes.emplace_back();
        for (const FrameResult& f : r.frames) {
            if (f.warmup || f.rays == 0) continue;
            out.counts.counters += f.counters, out.counts.memory_bytes += f.memory_bytes;
            const FrameObservation o = observation_of(f, double(r.objects));
            frames.push_back({update ? update->per_frame_ns(o) : double(f.update_ns), double(f.rays), o});
        }
    }
    return out;
}

double replay_cost(const CostCoefficients& c, const CountingReplay& replay) {
    double total = 0;
    for (const std::vector<CountingReplay::Frame>& frames : replay.scenes) {
        std::vector<double> frame_ms;
        for (const CountingReplay::Frame& f : frames)
            frame_ms.push_back((f.update_ns + f.rays * c.per_ray(f.observation)) / 1e6);
        total += spread_of(frame_ms).median;
    }
    return total / double(replay.scenes.size());
}

double predict_cost(const CostCoefficients& c, const TuneCategory& category, const std::string& structure,
                    const json& searched, std::uint32_t warmup_frames, ReplayCounts* counts,
                    const UpdatePrices* update) {
    const CountingReplay replay = counting_replay(category, structure, searched, warmup_frames, update);
    if (counts) counts->counters += replay.counts.counters, counts->memory_bytes += replay.counts.memory_bytes;
    return replay_cost(c, replay);
}

const ModelInputs& MachinePriors::of(const std::string& structure) {
    auto it = measured_.find(structure);
    if (it == measured_.end()) {
        ModelInputs in;
        in.caches = read_cache_sizes();
        const std::vector<CalibrationPoint> points =
            calibrate_if_buildable(structure, find_structure(structure).defaults());
        if (!points.empty()) in.calibrations.push_back(fit_calibration(structure, points));
        it = measured_.emplace(structure, std::move(in)).first;
    }
    return it->second;
}

namespace {

/// `structure`'s priors from `priors`, asked for only when a fit needs them; none without `priors`.
std::function<const ModelInputs&()> priors_of(MachinePriors* priors, const std::string& structure) {
    if (!priors) return {};
    return [priors, structure]() -> const ModelInputs& { return priors->of(structure); };
}

}  // namespace

SpaceSurvey survey_space(const std::vector<json>& all, const CostCoefficients& coefficients,
                         const std::function<CountingReplay(const json&)>& replay) {
    SpaceSurvey out;
    std::vector<ReplayCounts> counts;
    for (const json& p : all) {
        out.replays.push_back(replay(p));
        out.predicted.push_back(replay_cost(coefficients, out.replays.back()));
        counts.push_back(out.replays.back().counts);
    }
    out.class_of = equality_classes(counts, [](const ReplayCounts& a, const ReplayCounts& b) { return a == b; });
    return out;
}

std::optional<std::vector<double>> refit_predictions(const std::vector<FrameObservation>& frames,
                                                     std::size_t timed_configurations,
                                                     const std::vector<CountingReplay>& replays, MachinePriors* priors,
                                                     const std::string& structure) {
    if (timed_configurations < kMinRefitConfigurations) return std::nullopt;
    const std::optional<CostCoefficients> c = fit_coefficients(frames, priors_of(priors, structure));
    if (!c || !prices_ray_work(*c)) return std::nullopt;
    std::vector<double> out;
    for (const CountingReplay& r : replays) out.push_back(replay_cost(*c, r));
    return out;
}

Predictor calibrate_predictor(const TuneSpec& spec, const TuneCategory& category, const std::string& structure,
                              MachinePriors* priors) {
    Predictor out;
    const std::vector<SearchDimension>& dims = spec.space.at(structure);
    json defaults_searched = json::object();
    for (const SearchDimension& d : dims) defaults_searched[d.name] = find_structure(structure).defaults()[d.name];
    // Calibrate eq. 5.4 on the defaults plus seeded random points of the space, measured.
    std::vector<FrameObservation> frames;
    Random rng(mix_seed(spec.seed, 7));
    std::vector<json> points{defaults_searched};
    const std::vector<json> all = enumerate_space(dims);
    for (std::size_t k = 0; points.size() < std::min(spec.calibration, all.size()) && k < 100 * spec.calibration; ++k) {
        const json& p = all[rng.below(all.size())];
        if (std::find(points.begin(), points.end(), p) == points.end()) points.push_back(p);
    }
    SimulationOptions calibrate;
    calibrate.verify = false;
    calibrate.warmup_frames = spec.warmup_frames;
    int group = 0;
    for (const json& p : points) {
        const json params = complete(structure, p);
        const auto runs = run_simulations(category, structure, params, calibrate, 1);
        for (std::size_t s = 0; s < runs.size(); ++s)
            add_observations(runs[s], category.scenes[s].name, category_of(category.scenes[s]), group * 100 + int(s),
                             frames);
        ++group;
        ++out.measurements;
    }
    const std::optional<CostCoefficients> fitted = fit_coefficients(frames, priors_of(priors, structure), &out.update);
    if (!fitted)
        throw std::runtime_error("tune: the calibration of " + structure + " on " + category.name +
                                 " gave no cost model");
    out.coefficients = *fitted;
    out.model = fitted->model;
    out.predict = [c = *fitted, structure, warmup = spec.warmup_frames, cat = &category](const json& p) {
        return predict_cost(c, *cat, structure, p, warmup);
    };
    return out;
}

double spearman(const std::vector<double>& a, const std::vector<double>& b) {
    if (a.size() != b.size() || a.size() < 2) return NAN;
    auto ranks = [](const std::vector<double>& v) {
        std::vector<std::size_t> order(v.size());
        for (std::size_t i = 0; i < v.size(); ++i) order[i] = i;
        std::sort(order.begin(), order.end(), [&](std::size_t x, std::size_t y) { return v[x] < v[y]; });
        std::vector<double> r(v.size());
        for (std::size_t i = 0; i < order.size();) {
            std::size_t j = i;
            while (j + 1 < order.size() && v[order[j + 1]] == v[order[i]]) ++j;
            for (std::size_t k = i; k <= j; ++k) r[order[k]] = (double(i) + double(j)) / 2 + 1;  // ties: mean rank
            i = j + 1;
        }
        return r;
    };
    const std::vector<double> ra = ranks(a), rb = ranks(b);
    const double n = double(a.size()), mean = (n + 1) / 2;
    double sab = 0, saa = 0, sbb = 0;
    for (std::size_t i = 0; i < a.size(); ++i) {
        sab += (ra[i] - mean) * (rb[i] - mean);
        saa += (ra[i] - mean) * (ra[i] - mean);
        sbb += (rb[i] - mean) * (rb[i] - mean);
    }
    return saa > 0 && sbb > 0 ? sab / std::sqrt(saa * sbb) : NAN;
}

namespace {

/// Configurations in a space, without listing them.
double space_size(const std::vector<SearchDimension>& dims) {
    double n = 1;
    for (const SearchDimension& d : dims) n *= double(std::max<std::size_t>(1, d.levels.size()));
    return n;
}

/// The measured mode's ranked method on one structure (rank_then_time): every configuration of
/// the space replayed (rays counted, the update timed) and priced by `prior`, the configurations that count alike
/// merged, the best-ranked timed through `measure` (which appends their frames to `observed`), the model refitted on
/// those frames as they come. Returns what was timed, in order, as a search result.
SearchResult ranked_tuning(const TuneSpec& spec, const TuneCategory& category, const std::string& structure,
                           const CostCoefficients& prior, MachinePriors* priors,
                           const std::function<Candidate&(const json&)>& measure,
                           const std::vector<FrameObservation>& observed, StructureTuning& st) {
    const std::vector<SearchDimension>& dims = spec.space.at(structure);
    const std::vector<json> all = enumerate_space(dims);
    SpaceSurvey survey = survey_space(
        all, prior, [&](const json& p) { return counting_replay(category, structure, p, spec.warmup_frames); });
    const RankedResult r = rank_then_time(
        survey.class_of, survey.predicted, spec.budget,
        [&](std::size_t i) { return constrained_cost(*measure(all[i]).measured, spec.accuracy); },
        [&](const std::vector<std::size_t>& timed) {
            return refit_predictions(observed, timed.size(), survey.replays, priors, structure);
        });
    st.space_replays = std::move(survey.replays);
    st.refits = r.refits;
    SearchResult out;
    out.algorithm = "ranked by the cost model, the best-ranked timed (start: " + prior.model + ")";
    out.space_size = all.size();
    out.stop_reason = r.timed.size() >= spec.budget ? "budget" : "enumerated";
    for (std::size_t k = 0; k < r.timed.size(); ++k) {
        out.evaluations.push_back({all[r.timed[k]], r.costs[k]});
        measure(all[r.timed[k]]).predicted_ms = r.predicted_when_timed[k];  // measured already: a lookup
    }
    out.best = r.best;
    for (const SearchDimension& d : dims) {
        const json& v = out.evaluations.empty() ? json() : out.evaluations[out.best].params[d.name];
        if (d.levels.size() >= 2 && (v == d.levels.front() || v == d.levels.back())) out.on_bound.push_back(d.name);
    }
    return out;
}

/// The measured mode on one structure: the ranked method where the machine's calibration gives a
/// model and the space is small enough to replay whole, else the search from the defaults. Either
/// way the frames measured, counted by untimed replays, fit the model advise applies.
void tune_measured(const TuneSpec& spec, const TuneCategory& category, const std::string& structure,
                   MachinePriors* priors, const std::function<Candidate&(const json&, bool)>& measure_candidate,
                   const std::vector<FrameObservation>& observed, StructureTuning& st) {
    const std::vector<SearchDimension>& dims = spec.space.at(structure);
    json defaults_searched = json::object();
    for (const SearchDimension& d : dims) defaults_searched[d.name] = find_structure(structure).defaults()[d.name];
    const std::optional<CostCoefficients> prior = prior_coefficients(priors, structure);
    if (prior && space_size(dims) <= double(kRankedSpaceLimit)) {
        st.search = ranked_tuning(
            spec, category, structure, *prior, priors,
            [&](const json& p) -> Candidate& { return measure_candidate(p, p == defaults_searched); }, observed, st);
    } else {
        // The defaults start the search and count against the budget.
        measure_candidate(defaults_searched, true);
        st.search = search_levels(
            dims, [&](const json& p) { return constrained_cost(*measure_candidate(p, false).measured, spec.accuracy); },
            spec.budget, spec.seed, defaults_searched);
    }
    st.cost_model = fit_coefficients(observed, priors_of(priors, structure), &st.update_model);
    // Too few configurations timed to fit: the ranking's own model, the calibration alone.
    if (!st.cost_model && prior) st.cost_model = prior;
}

}  // namespace

CategoryTuning tune_category(const TuneSpec& spec, const TuneCategory& category, MachinePriors* priors) {
    CategoryTuning out;
    out.category = category.name;
    std::vector<std::string> unmet;  // structures with no candidate that meets the accuracy
    for (const std::string& structure : spec.structures) {
        const Clock::time_point start = Clock::now();
        StructureTuning st;
        st.structure = structure;
        st.mode = spec.mode;
        const std::vector<SearchDimension>& dims = spec.space.at(structure);
        std::map<std::string, std::size_t> measured_index;  // params dump → candidate
        std::vector<FrameObservation> observed;             // the measured mode's counted frames
        auto measure_candidate = [&](const json& searched, bool is_default) -> Candidate& {
            const json params = complete(structure, searched);
            auto it = measured_index.find(params.dump());
            if (it == measured_index.end()) {
                Candidate c{structure, params, std::nullopt,
                            measure(category, structure, params, spec.warmup_frames, spec.repetitions,
                                    spec.accuracy.needs_verification(), spec.mode == "measured" ? &observed : nullptr,
                                    int(st.candidates.size())),
                            is_default};
                ++st.measurements;
                st.candidates.push_back(c);
                it = measured_index.emplace(params.dump(), st.candidates.size() - 1).first;
            }
            st.candidates[it->second].is_default = st.candidates[it->second].is_default || is_default;
            return st.candidates[it->second];
        };
        json defaults_searched = json::object();
        for (const SearchDimension& d : dims) defaults_searched[d.name] = find_structure(structure).defaults()[d.name];
        if (spec.mode == "measured") {
            tune_measured(spec, category, structure, priors, measure_candidate, observed, st);
        } else {
            measure_candidate(defaults_searched, true);
            Predictor predictor = calibrate_predictor(spec, category, structure, priors);
            st.measurements += predictor.measurements;
            st.prediction_model = predictor.model;
            st.predict = predictor.predict;
            st.prediction_measurements = predictor.measurements;
            st.cost_model = predictor.coefficients;
            st.update_model = predictor.update;
            const auto& predict = predictor.predict;
            st.search = search_levels(dims, predict, spec.budget, spec.seed, defaults_searched);
            // Verify: measure the best predicted candidates (the defaults are measured already).
            std::vector<std::size_t> order(st.search.evaluations.size());
            for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
            std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
                return st.search.evaluations[a].cost < st.search.evaluations[b].cost;
            });
            const std::size_t verify = spec.mode == "predicted" ? 1 : spec.verify_top;
            for (std::size_t i = 0; i < std::min(verify, order.size()); ++i) {
                const Evaluation& e = st.search.evaluations[order[i]];
                measure_candidate(e.params, false).predicted_ms = e.cost;
            }
            // The defaults' prediction, for the report.
            for (Candidate& c : st.candidates)
                if (c.is_default && !c.predicted_ms) c.predicted_ms = predict(defaults_searched);
        }
        st.seconds = std::chrono::duration<double>(Clock::now() - start).count();
        std::optional<std::size_t> best;
        for (std::size_t i = 0; i < st.candidates.size(); ++i)
            if (spec.accuracy.met_by(st.candidates[i].measured->accuracy) &&
                (!best || st.candidates[i].measured->ms < st.candidates[*best].measured->ms))
                best = i;
        if (!best) {
            unmet.push_back(structure);
            continue;
        }
        st.best_candidate = *best;
        out.structures.push_back(std::move(st));
    }
    if (out.structures.empty())
        throw InputError("tune: no configuration of " + join(unmet, ", ") + " on category " + category.name +
                         " meets --accuracy " + spec.accuracy.text());

    // Fastest measured overall among those that meet the accuracy, then the simplest within 3% of it.
    std::vector<const Candidate*> candidates;
    for (const StructureTuning& st : out.structures)
        for (const Candidate& c : st.candidates) candidates.push_back(&c);
    const std::vector<const Candidate*> all = meeting(candidates, spec.accuracy);
    const Candidate* fastest = *std::min_element(all.begin(), all.end(), [](const Candidate* a, const Candidate* b) {
        return a->measured->ms < b->measured->ms;
    });
    const Candidate* chosen = all[simplest_within(all, 0.03)];
    out.fastest = *fastest;
    out.chosen = *chosen;
    if (chosen != fastest)
        out.rule_note = "the simplicity rule chose " + out.chosen.structure + " " + out.chosen.params.dump() + " (" +
                        std::to_string(out.chosen.measured->ms) + " ms) over the fastest, " + fastest->structure + " " +
                        fastest->params.dump() + " (" + std::to_string(fastest->measured->ms) +
                        " ms): within 3% and simpler";
    if (!unmet.empty())
        out.rule_note += std::string(out.rule_note.empty() ? "" : "; ") + "no configuration of " + join(unmet, ", ") +
                         " met --accuracy " + spec.accuracy.text();
    return out;
}

}  // namespace rcb
