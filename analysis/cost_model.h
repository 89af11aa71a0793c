#pragma once
/// The thesis' performance model fitted to measurements (§5.1, eq. 5.4 and 5.5).
///
/// Ray cast, per structure, per ray:   C = C_RB·N_RB + C_T·N_T + C_PREP      (N_RB = N_TP + N_FP)
///                       with shapes:  … + C_RO·N_RO                         (eq. 5.3: the narrow phase)
/// Update, per structure, per frame:   U = c_ins·inserts + c_rem·removes + c_mov·moves
///                                         + c_obj·objects (rebuilding structures) + c_frame
///
/// Observations are the frames of a run (not warm-up): the timed batch's time over its rays
/// against the counting pass's mean counters. Nested candidate models are compared by held-out
/// error (k-fold over scene families) and the smallest within the tolerance of the best is kept:
/// model no more than the data needs. The ray-cast coefficients are drawn towards the calibration
/// pass's values (runner/calibration.h) and kept within 3× of them; a term without a calibration
/// value that the run's data put at 0 is dropped and the model says why. Where a structure ran
/// shape tests (N_RO > 0 in some frame) every form carries C_RO·N_RO (eq. 5.3). Every structure is
/// also validated leaving one scene family out.
///
/// The terms, their counters and the candidate forms are one table (analysis/model_terms.h): the
/// fit, the breakdown, the stored coefficients and the tuner read it.

#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "analysis/linear_fit.h"
#include "analysis/model_terms.h"
#include "analysis/repetitions.h"
#include "runner/calibration.h"
#include "runner/results_reader.h"

namespace rcb {

/// Which cache tier `bytes` falls in: the number of `caches` (by level, data and unified) smaller
/// than it, at most 3.
int memory_tier_of(double bytes, const std::vector<CacheLevel>& caches);

/// A ray-cast coefficient measured by the calibration pass (runner/calibration.h): the micro-scenes'
/// fit of eq. 5.4. `pinned` when the micro-scenes determine it (positive, interval within ±50%);
/// otherwise `why` says what was wrong and the term gets no prior.
struct CalibratedTerm {
    std::string name;  ///< a term with a prior in the table (model_terms.h): "C_RB", "C_T", "C_MP", …
    double value = NAN, ci_low = NAN, ci_high = NAN;
    bool pinned = false;
    std::string why;
};
struct StructureCalibration {
    std::string structure;
    std::vector<CalibrationPoint> points;
    std::vector<CalibratedTerm> terms;
    double condition_number = NAN;
    const CalibratedTerm* term(const std::string& name) const;
};
/// Eq. 5.4 fitted to the micro-scenes, each term with a prior that some point counts, and the
/// constants. A structure that counts no N_MISS is fitted without the scenes that outgrow the
/// cache; one whose C_HIT the micro-scenes cannot pin, without C_HIT and the scene that prices it
/// (`points` holds those fitted).
StructureCalibration fit_calibration(const std::string& structure, const std::vector<CalibrationPoint>& all);

/// What the fit knows about the run beyond its frames: the calibration per structure (may be empty:
/// then no priors) and the machine's caches (may be empty).
struct ModelInputs {
    std::vector<StructureCalibration> calibrations;
    std::vector<CacheLevel> caches;
};

/// Leave one scene family out (scene_family, model_terms.h): for each family, the frames of the fit
/// (every other family's) and the frames predicted (the family's own), as indices into `frames`.
struct SceneSplit {
    std::string scene;  ///< the family left out
    std::vector<std::size_t> train, test;
};
std::vector<SceneSplit> scene_splits(const std::vector<const FrameObservation*>& frames);

/// One scene family predicted from a fit on every other family: mean over its cells of the
/// relative error of the median predicted time per frame (update + rays × C) against the median
/// measured; NaN when no other family measured the structure. `scene` names the family.
struct SceneError {
    std::string scene;
    double frame_error = NAN, raycast_error = NAN;
};

/// Frames of one run; `run` is a run id, or 0 for the newest run (of `experiment` if given).
std::int64_t resolve_run(Database& db, std::int64_t run, const std::string& experiment);
/// `fastest_cast` (the default): one observation per frame of a cell, its fastest ray cast and
/// median update over the cell's repetitions; `fastest`: one per frame, its fastest of both;
/// `median`: every repetition's frames.
std::vector<FrameObservation> load_observations(Database& db, std::int64_t run,
                                                OverRepetitions how = OverRepetitions::fastest_cast);

struct CandidateModel {
    std::string name;    ///< a form of model_forms(): "eq5.4", "with-coherence", …
    std::string target;  ///< "raycast" or "update"
    LinearProblem problem;
    LinearFit fit;
    double heldout_error = 0;  ///< mean absolute relative error on held-out configurations
    bool chosen = false;
    std::vector<std::string> dropped;  ///< terms left out of this model, each with why
};

/// What a structure's model was fitted on, per counter: the least and the most of its cells'
/// medians (changes per frame, objects, N_RB and N_T per ray, and N_TP per ray where the chosen
/// ray-cast model prices a hit apart, C_HIT). A cell beyond it by more than
/// kRangeMargin is priced by extrapolation: a physics frame moving all 10^4 bodies, priced from
/// thesis frames of at most a few hundred changes, missed by 5–10× (docs/model.md).
struct TrainedRange {
    std::string counter;
    double low = 0, high = 0;
};
inline constexpr double kRangeMargin = 2.0;

struct StructureModels {
    std::string structure;
    std::vector<std::string> unused_terms;  ///< terms that are always 0 for this structure (e.g. N_T of bf)
    std::vector<CandidateModel> raycast, update;
    /// Leave one family out, refitting only the chosen models' coefficients (the left-out family
    /// helped choose the form: optimistic; analysis/validation.h redoes the whole selection).
    std::vector<SceneError> loso;
    double loso_error = NAN;  ///< mean frame_error over the families that could be predicted
    double loso_raycast_error = NAN;
    const StructureCalibration* calibration = nullptr;  ///< into the ModelInputs given, if any
    std::vector<TrainedRange> trained;                  ///< the ranges of the frames fitted
    /// The chosen models frozen, form and coefficients as fitted here: ns per ray and ns of update of
    /// any frame (another scene's, another run's) from its counters; NaN where a
    /// per-configuration form has no column for the frame's configuration. Empty
    /// unless both targets have a chosen model (analysis/validation.h).
    std::function<double(const FrameObservation&)> predict_ray, predict_update;
    const CandidateModel* chosen(const std::string& target) const;
};

/// The counters of a cell (its frames) beyond `m.trained` by more than kRangeMargin, as
/// "changes per frame 10000 (fitted on 20.0–448)", joined by "; "; "" within.
std::string outside_trained_range(const StructureModels& m, const std::vector<const FrameObservation*>& cell);

/// Held-out errors within max(0.5 points, 5% of the best) count as "as good as the best".
inline constexpr double kSelectionTolerance = 0.05;
inline constexpr double kSelectionFloor = 0.005;

/// What a term of a model buys: the model's held-out error (cross_validated_error, k-fold over scene
/// families) refitted without the term, beside `m.heldout_error` with it. One per term, in the
/// model's order; NaN where the model without it cannot be validated (a single term, too few families).
struct TermWorth {
    std::string term;
    double without = NAN;
};
std::vector<TermWorth> term_worth(const CandidateModel& m);

/// `inputs` (kept alive by the caller while the result is used) gives the priors.
std::vector<StructureModels> fit_cost_models(const std::vector<FrameObservation>& frames,
                                             const ModelInputs& inputs = {});
/// The run's stored calibration and caches (empty for runs made before they were stored).
ModelInputs load_model_inputs(Database& db, std::int64_t run);

/// Replaces the run's stored fits (schema: docs/database.md, tables fit and fit_coefficient).
void store_fits(Database& db, std::int64_t run, const std::vector<StructureModels>& models);

/// A ray-cast term's share of one row of the Table 6.3 analog.
struct TermShare {
    std::string name;          ///< the term (cost_terms(): those the breakdown shows)
    double count = 0;          ///< its value per ray, mean over frames (C_RB's: N_TP + N_FP)
    double coefficient = NAN;  ///< from the chosen model, 0 where it lacks the term, NaN without a chosen model
    double product = 0;        ///< coefficient × count (0 without a chosen model)
};

/// Thesis Table 6.3 analog: one row per (scene, configuration).
struct CostBreakdown {
    std::string scene, structure, params;
    double c_total = 0;                  ///< measured ns per ray (median over frames)
    double n_tp = 0, n_fp = 0, n_t = 0;  ///< the thesis' counts per ray (Tables 6.3, 6.4): N_RB as N_TP + N_FP, and N_T
    std::vector<TermShare> terms;        ///< one per term of cost_terms() the breakdown shows, in its order
    /// The share of term `name`; std::logic_error for a term the breakdown does not show.
    const TermShare& term(const std::string& name) const;
};
std::vector<CostBreakdown> cost_breakdown(const std::vector<FrameObservation>& frames,
                                          const std::vector<StructureModels>& models);

/// The Table 6.3 analog's cost and count columns as `fit` and the report print them: C_total, the
/// terms, the counts and the coefficients, with C_MP·N_MP and N_MP only where a chosen model prices
/// unpredicted steps and C_RO·N_RO and N_RO only where a configuration tested shapes (eq. 5.3).
/// `times` spells the product in the header ("x" or "×"); each row's text follows its breakdown's.
struct BreakdownColumns {
    std::vector<std::string> header;
    std::vector<std::vector<std::string>> rows;
};
BreakdownColumns breakdown_columns(const std::vector<CostBreakdown>& breakdown, const std::string& times);

/// The fit stage's entry point: the run's frames fitted per structure (fit_cost_models), the fits
/// stored in the database (store_fits), and the Table 6.3 analog.
struct RunFit {
    std::int64_t run = 0;
    std::size_t frames = 0;
    std::shared_ptr<const ModelInputs> inputs;  ///< what `models` point into
    std::vector<StructureModels> models;
    std::vector<CostBreakdown> breakdown;
};
RunFit fit_run(Database& db, std::int64_t run, OverRepetitions how = OverRepetitions::fastest_cast);

/// "uniform", "irregular", "import", "recording": the category of a scene from its stored spec.
std::string scene_category(const std::string& spec_json);
/// The scene's ray mode from its stored spec ("center", "dense,los", …); "" when it names none.
std::string scene_ray_mix(const std::string& spec_json);

}  // namespace rcb
