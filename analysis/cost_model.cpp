#include "analysis/cost_model.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/simulator.h"
#include "runner/store.h"

namespace rcb {

std::string scene_category(const std::string& spec_text) {
    const nlohmann::json spec = nlohmann::json::parse(spec_text, nullptr, false);
    if (spec.is_object()) {
        if (spec.contains("kind")) return spec["kind"].get<std::string>();
        if (spec.contains("import")) return "import";
        if (spec.contains("recording")) return "recording";
    }
    return "other";
}

namespace {

/// A term: its name and how to read it from a frame.
struct Term {
    std::string name;
    double (*value)(const FrameObservation&);
};

const Term kNrb{"C_RB", [](const FrameObservation& f) { return f.n_rb; }};
const Term kNt{"C_T", [](const FrameObservation& f) { return f.n_t; }};
const Term kPrep{"C_PREP", [](const FrameObservation&) { return 1.0; }};
const Term kMemory{"C_MEM", [](const FrameObservation& f) { return f.memory_mb; }};
const Term kInsert{"c_insert", [](const FrameObservation& f) { return f.inserts; }};
const Term kRemove{"c_remove", [](const FrameObservation& f) { return f.removes; }};
const Term kMove{"c_move", [](const FrameObservation& f) { return f.moves; }};
const Term kObjects{"c_object", [](const FrameObservation& f) { return f.objects; }};
const Term kFrame{"c_frame", [](const FrameObservation&) { return 1.0; }};

/// Builds the problem for `terms`; with `categories`, every term is split per category (the
/// column is the term where the frame's category matches, else 0).
LinearProblem build_problem(const std::vector<const FrameObservation*>& frames, const std::vector<Term>& terms,
                            const std::string& target, const std::vector<std::string>& categories = {}) {
    LinearProblem p;
    const std::vector<std::string> cats = categories.empty() ? std::vector<std::string>{""} : categories;
    for (const std::string& c : cats)
        for (const Term& t : terms) p.terms.push_back(c.empty() ? t.name : t.name + "[" + c + "]");
    for (const FrameObservation* f : frames) {
        const double y = target == "raycast" ? f->raycast_ns / f->rays : f->update_ns;
        if (!(y > 0)) continue;  // a zero time (timer resolution) carries no relative information
        std::vector<double> row;
        for (const std::string& c : cats)
            for (const Term& t : terms) row.push_back(c.empty() || c == f->category ? t.value(*f) : 0.0);
        p.x.push_back(std::move(row));
        p.y.push_back(y);
        p.group.push_back(f->config_group);
    }
    return p;
}

/// Drops terms that are 0 in every frame (they cannot be fitted and the structure does not have them).
std::vector<Term> present(const std::vector<const FrameObservation*>& frames, const std::vector<Term>& terms,
                          std::vector<std::string>& unused) {
    std::vector<Term> out;
    for (const Term& t : terms) {
        const bool any =
            std::any_of(frames.begin(), frames.end(), [&](const FrameObservation* f) { return t.value(*f) != 0; });
        if (any)
            out.push_back(t);
        else if (std::find(unused.begin(), unused.end(), t.name) == unused.end())
            unused.push_back(t.name);
    }
    return out;
}

void select(std::vector<CandidateModel>& models) {
    double best = INFINITY;
    for (const CandidateModel& m : models)
        if (std::isfinite(m.heldout_error) && m.fit.status() == "ok") best = std::min(best, m.heldout_error);
    if (!std::isfinite(best)) {  // nothing trustworthy: keep the smallest model that fitted at all, flagged
        if (!models.empty()) models.front().chosen = true;
        return;
    }
    const double tolerance = std::max(kSelectionFloor, kSelectionTolerance * best);
    // Candidates are listed from the smallest to the largest.
    for (CandidateModel& m : models)
        if (m.fit.status() == "ok" && m.heldout_error <= best + tolerance) {
            m.chosen = true;
            return;
        }
}

CandidateModel candidate(const std::string& name, const std::string& target, LinearProblem problem) {
    CandidateModel m;
    m.name = name;
    m.target = target;
    m.problem = std::move(problem);
    m.fit = fit_linear(m.problem);
    m.heldout_error = cross_validated_error(m.problem);
    return m;
}

}  // namespace

const CandidateModel* StructureModels::chosen(const std::string& target) const {
    for (const CandidateModel& m : target == "raycast" ? raycast : update)
        if (m.chosen) return &m;
    return nullptr;
}

std::int64_t resolve_run(Database& db, std::int64_t run, const std::string& experiment) {
    if (run) {
        Statement s = db.prepare("SELECT id FROM run WHERE id = ?");
        s.bind(1, run);
        if (!s.step()) throw InputError("--run " + std::to_string(run) + ": no such run in " + db.path());
        return run;
    }
    Statement s = db.prepare(
        experiment.empty()
            ? "SELECT run.id FROM run WHERE EXISTS (SELECT 1 FROM cell WHERE cell.run_id = run.id) ORDER BY run.id "
              "DESC LIMIT 1"
            : "SELECT run.id FROM run JOIN experiment ON experiment.id = run.experiment_id WHERE experiment.name = ? "
              "AND EXISTS (SELECT 1 FROM cell WHERE cell.run_id = run.id) ORDER BY run.id DESC LIMIT 1");
    if (!experiment.empty()) s.bind(1, experiment);
    if (!s.step())
        throw InputError(experiment.empty()
                             ? db.path() + ": the database has no measured run"
                             : "--experiment " + experiment + ": no measured run of that experiment in " + db.path());
    return s.int64(0);
}

std::vector<FrameObservation> load_observations(Database& db, std::int64_t run) {
    std::vector<FrameObservation> out;
    std::map<std::tuple<std::int64_t, std::int64_t>, int> groups;
    Statement s = db.prepare(
        "SELECT config.structure, config.params, scene.name, scene.spec, cell.scene_id, cell.config_id, frame.rays, "
        "frame.raycast_ns, frame.update_ns, frame.n_t, frame.n_rb, frame.n_tp, frame.inserts, frame.removes, "
        "frame.moves, "
        "cell.objects, frame.memory_bytes FROM frame JOIN cell ON cell.id = frame.cell_id JOIN config ON config.id = "
        "cell.config_id "
        "JOIN scene ON scene.id = cell.scene_id WHERE cell.run_id IN " +
        std::string(kRunGroupSql) + " AND frame.warmup = 0 ORDER BY cell.id, frame.frame");
    s.bind_all(run, run);
    while (s.step()) {
        FrameObservation f;
        f.structure = s.text(0);
        f.params = s.text(1);
        f.scene = s.text(2);
        f.category = scene_category(s.text(3));
        const auto key = std::make_tuple(s.int64(4), s.int64(5));
        f.config_group = groups.emplace(key, int(groups.size())).first->second;
        f.rays = s.real(6);
        f.raycast_ns = s.real(7);
        f.update_ns = s.real(8);
        if (f.rays > 0) f.n_t = s.real(9) / f.rays, f.n_rb = s.real(10) / f.rays, f.n_tp = s.real(11) / f.rays;
        f.inserts = s.real(12);
        f.removes = s.real(13);
        f.moves = s.real(14);
        f.objects = s.real(15);
        f.memory_mb = s.real(16) / (1024.0 * 1024.0);
        out.push_back(f);
    }
    if (out.empty()) throw InputError("run " + std::to_string(run) + " has no measured frames to fit");
    return out;
}

std::vector<StructureModels> fit_cost_models(const std::vector<FrameObservation>& frames) {
    std::map<std::string, std::vector<const FrameObservation*>> by_structure;
    for (const FrameObservation& f : frames) by_structure[f.structure].push_back(&f);
    std::vector<StructureModels> out;
    for (const auto& [structure, fs] : by_structure) {
        StructureModels m;
        m.structure = structure;
        std::vector<const FrameObservation*> with_rays;
        for (const FrameObservation* f : fs)
            if (f->rays > 0) with_rays.push_back(f);
        std::set<std::string> category_set;
        for (const FrameObservation* f : with_rays) category_set.insert(f->category);
        const std::vector<std::string> categories(category_set.begin(), category_set.end());

        // Ray cast: from the smallest model to the largest.
        const std::vector<Term> core = present(with_rays, {kNrb, kNt}, m.unused_terms);
        std::vector<Term> full = core;
        full.push_back(kPrep);
        m.raycast.push_back(candidate("no-prep", "raycast", build_problem(with_rays, core, "raycast")));
        m.raycast.push_back(candidate("eq5.4", "raycast", build_problem(with_rays, full, "raycast")));
        std::vector<Term> with_memory = full;
        with_memory.push_back(kMemory);
        m.raycast.push_back(candidate("with-memory", "raycast", build_problem(with_rays, with_memory, "raycast")));
        if (categories.size() > 1)
            m.raycast.push_back(
                candidate("per-category", "raycast", build_problem(with_rays, full, "raycast", categories)));
        select(m.raycast);

        // Update: per-operation costs, then a per-object (rebuild) cost.
        std::vector<std::string> unused_update;
        const std::vector<Term> ops = present(fs, {kInsert, kRemove, kMove}, unused_update);
        std::vector<Term> ops_frame = ops;
        ops_frame.push_back(kFrame);
        std::vector<Term> rebuild = ops_frame;
        rebuild.push_back(kObjects);
        m.update.push_back(candidate("per-operation", "update", build_problem(fs, ops_frame, "update")));
        m.update.push_back(candidate("with-rebuild", "update", build_problem(fs, rebuild, "update")));
        select(m.update);
        out.push_back(std::move(m));
    }
    return out;
}

void store_fits(Database& db, std::int64_t run, const std::vector<StructureModels>& models) {
    Transaction t(db);
    db.prepare("DELETE FROM fit WHERE run_id = ?").bind(1, run).run();
    for (const StructureModels& s : models)
        for (const auto* list : {&s.raycast, &s.update})
            for (const CandidateModel& m : *list) {
                db.prepare(
                      "INSERT INTO fit(run_id, created_at, structure, target, model, terms, observations, "
                      "configurations, r2, "
                      "rmse_relative, heldout_error, condition_number, status, chosen) VALUES "
                      "(?,?,?,?,?,?,?,?,?,?,?,?,?,?)")
                    .bind_all(run, utc_now(), s.structure, m.target, m.name, nlohmann::json(m.problem.terms).dump(),
                              std::int64_t(m.fit.observations), std::int64_t(m.fit.groups), m.fit.r2,
                              m.fit.rmse_relative, std::isfinite(m.heldout_error) ? m.heldout_error : -1.0,
                              std::isfinite(m.fit.condition_number) ? m.fit.condition_number : 1e300, m.fit.status(),
                              std::int64_t(m.chosen))
                    .run();
                const std::int64_t fit = db.last_insert_id();
                for (const Coefficient& c : m.fit.coefficients) {
                    Statement ins = db.prepare(
                        "INSERT INTO fit_coefficient(fit_id, name, value, ci_low, ci_high, spans_zero) VALUES "
                        "(?,?,?,?,?,?)");
                    ins.bind_all(fit, c.name, c.value);
                    ins.bind(4, std::isfinite(c.ci_low) ? std::optional<double>(c.ci_low) : std::nullopt);
                    ins.bind(5, std::isfinite(c.ci_high) ? std::optional<double>(c.ci_high) : std::nullopt);
                    ins.bind(6, std::int64_t(c.spans_zero));
                    ins.run();
                }
            }
    t.commit();
}

std::vector<CostBreakdown> cost_breakdown(const std::vector<FrameObservation>& frames,
                                          const std::vector<StructureModels>& models) {
    std::map<std::tuple<std::string, std::string, std::string>, std::vector<const FrameObservation*>> rows;
    for (const FrameObservation& f : frames)
        if (f.rays > 0) rows[{f.scene, f.structure, f.params}].push_back(&f);
    std::vector<CostBreakdown> out;
    for (const auto& [key, fs] : rows) {
        CostBreakdown b;
        std::tie(b.scene, b.structure, b.params) = key;
        std::vector<double> cost;
        for (const FrameObservation* f : fs) {
            cost.push_back(f->raycast_ns / f->rays);
            b.n_tp += f->n_tp, b.n_fp += f->n_rb - f->n_tp, b.n_t += f->n_t;
        }
        const double n = double(fs.size());
        b.n_tp /= n, b.n_fp /= n, b.n_t /= n;
        b.c_total = spread_of(cost).median;
        const std::string category = fs.front()->category;
        for (const StructureModels& s : models) {
            if (s.structure != b.structure) continue;
            const CandidateModel* m = s.chosen("raycast");
            if (!m) break;
            auto coefficient = [&](const std::string& name) {
                for (const Coefficient& c : m->fit.coefficients)
                    if (c.name == name || c.name == name + "[" + category + "]") return c.value;
                return 0.0;
            };
            b.c_rb = coefficient("C_RB");
            b.c_t = coefficient("C_T");
            b.prep = coefficient("C_PREP");
            b.rb_term = b.c_rb * (b.n_tp + b.n_fp);
            b.t_term = b.c_t * b.n_t;
        }
        out.push_back(b);
    }
    return out;
}

std::optional<RaycastCoefficients> stored_raycast_coefficients(Database& db, std::int64_t run,
                                                               const std::string& structure,
                                                               const std::string& category) {
    Statement s = db.prepare(
        "SELECT fit.model, fit_coefficient.name, fit_coefficient.value FROM fit JOIN fit_coefficient ON "
        "fit_coefficient.fit_id = fit.id "
        "WHERE fit.run_id = ? AND fit.structure = ? AND fit.target = 'raycast' AND fit.chosen = 1");
    s.bind_all(run, structure);
    std::optional<RaycastCoefficients> out;
    while (s.step()) {
        if (!out) out = RaycastCoefficients{0, 0, 0, s.text(0)};
        std::string name = s.text(1);
        const auto bracket = name.find('[');
        if (bracket != std::string::npos) {  // per-category: only this scene's category
            if (name.substr(bracket) != "[" + category + "]") continue;
            name = name.substr(0, bracket);
        }
        if (name == "C_RB")
            out->c_rb = s.real(2);
        else if (name == "C_T")
            out->c_t = s.real(2);
        else if (name == "C_PREP")
            out->c_prep = s.real(2);
    }
    return out;
}

RunFit fit_run(Database& db, std::int64_t run) {
    RunFit out;
    out.run = run;
    const std::vector<FrameObservation> frames = load_observations(db, run);
    out.frames = frames.size();
    out.models = fit_cost_models(frames);
    store_fits(db, run, out.models);
    out.breakdown = cost_breakdown(frames, out.models);
    return out;
}

}  // namespace rcb
