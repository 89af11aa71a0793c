#pragma once
/// Tuning structures' parameters per scene category (the thesis' future work, §7.2): minimise the
/// per-frame cost C_frame = C_update + N·C (eq. 5.5) over the parameters the registry marks
/// tunable. Tuning files are documented in experiments/README.md ("Tuning files").
///
/// Modes:
///   measured                 every evaluation runs the simulator (median over frames × repetitions).
///                            Where the machine's micro-scene calibration gives the structure a cost
///                            model, the whole space is replayed (rays counted, the update timed) and ranked by it, and
///                            the budget times the best-ranked (rank_then_time, tuner/search.h); else the search
///                            (search_levels) spends it
///   predicted                every evaluation is a cheap counting replay (no timed rays, no
///                            verification); C = C_RB·N_RB + C_T·N_T + … (eq. 5.4) with coefficients
///                            fitted to a few measured calibration points of the same structure
///                            and category; the update is the replay's own (timed) update
///   predicted-then-verified  search on the prediction, then measure the best few candidates and
///                            the defaults, and decide on the measurements (the default)
///
/// Among the measured candidates the simplest within 3% of the best is chosen: UG before HG before
/// other structures, then less memory (fewer cells). The report says when that rule decided.

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/cost_model.h"
#include "accel/model/counters.h"
#include "sim/simulator.h"
#include "runner/experiment.h"
#include "tuner/accuracy.h"
#include "tuner/search.h"

namespace rcb {

/// Made-up times for a simulation: replaces the build, update and ray-cast times the clock
/// measured (from the frame's counters, say). Tests only: a verdict that depends on how fast the
/// machine is can flip under load, so the tests of the tuner's and advise's choices give their
/// measurements costs of their own. No file or command-line option sets one.
using SimulationTiming = std::function<void(SimulationResult&)>;

struct TuneCategory {
    std::string name;
    std::vector<SceneSpec> scenes;
    /// Empty: the clock's times. Set: every simulation the tuner runs on the category (timed
    /// measurements, calibrations, counting replays) also runs the counting pass, then passes its
    /// result through `timing` before anything reads a time from it.
    SimulationTiming timing{};
};

struct TuneSpec {
    std::string name, description, content;
    std::string mode = "predicted-then-verified";
    std::vector<std::string> structures;                        ///< default: every structure with a tunable parameter
    std::map<std::string, std::vector<SearchDimension>> space;  ///< per structure
    std::size_t budget = 30;                                    ///< distinct evaluations per search
    std::size_t calibration = 6;                                ///< measured points that calibrate the prediction
    std::size_t verify_top = 3;                                 ///< candidates measured after a predicted search
    std::uint64_t seed = 1;
    std::uint32_t warmup_frames = 1;
    std::uint32_t repetitions = 2;
    std::vector<TuneCategory> categories;
    AccuracyConstraint accuracy;  ///< what the chosen configurations must answer (set_accuracy)
};

/// Sets the spec's accuracy constraint. One that allows inexact answers adds the query level
/// (accel/narrow/narrow_phase.h) to every structure's search space that does not name it already: the
/// candidate level and the narrow phase then compete with the box level on speed.
void set_accuracy(TuneSpec& spec, const AccuracyConstraint& accuracy);

/// Reads and validates (errors name the file and JSON path).
TuneSpec load_tune_spec(const std::string& path);
TuneSpec parse_tune_spec(const std::string& text, const std::string& name, const std::string& base_dir);

/// The default search space of a structure: its tunable parameters' levels (integers: every value
/// when there are at most 12, else powers of two; reals: ×2 steps on log-scaled parameters, 8
/// linear steps otherwise; booleans and choices: every value).
std::vector<SearchDimension> default_space(const std::string& structure);

/// A cost with its spread over frames and repetitions (ms per frame).
struct MeasuredCost {
    double ms = 0, mad = 0;
    double update_ms = 0, raycast_ms = 0;
    double memory_bytes = 0;
    MeasuredAccuracy accuracy;  ///< verified on the first repetition when asked
};

struct Candidate {
    std::string structure;
    nlohmann::json params;  ///< complete
    std::optional<double> predicted_ms;
    std::optional<MeasuredCost> measured;
    bool is_default = false;
};

// CostCoefficients (analysis/model_terms.h): eq. 5.4 as the predicted mode applies it, ns per ray,
// every ray-cast term of the cost-term table a tuning carries (C_RB·N_RB + C_T·N_T + C_PREP + …,
// C_HIT·N_TP included), 0 where the chosen model lacks it. Machine costs, not scene properties:
// fitted on one set of scenes, they price the counters of another (what advise does with a
// tuning's model on an unseen scene).

/// What a replay counted over its measured frames and scenes. Two configurations with equal
/// counts are one structure in effect (a hash grid of depth 0 ignores its capacity and
/// subdivision), so measuring both tells nothing new.
struct ReplayCounts {
    Counters counters;  ///< summed over the measured frames of every scene
    std::uint64_t memory_bytes = 0;
    friend bool operator==(const ReplayCounts&, const ReplayCounts&) = default;
};

/// The update's cost per frame (eq. 5.5's U) as a fit of measured frames prices it from a frame's
/// changes, writes and objects: what a prediction adds to the rays' cost instead of timing the
/// scene's update. Only a form whose every column is a plain term of the table (model_terms.h; no
/// per-tier or per-configuration copy) prices another scene's configurations from their counters
/// alone: the fit's chosen update form where it is one, else the plain form with the lowest
/// held-out error.
struct UpdatePrices {
    std::vector<std::pair<std::string, double>> terms;  ///< (an update term of cost_terms(), ns per its count)
    std::string model;                                  ///< the form and its held-out error

    double per_frame_ns(const FrameObservation& f) const;
    nlohmann::json to_json() const;
    /// InputError "<where>: …" for a term that is not a plain update term or a value that is not a
    /// finite number ≥ 0.
    static UpdatePrices from_json(const nlohmann::json& j, const std::string& where);
};
/// The prices of `models`' update fit (see UpdatePrices); none where no plain form was fitted.
std::optional<UpdatePrices> update_prices(const StructureModels& models);

/// A counting replay of a configuration on a category (no timed rays, no verification): what
/// predict_cost prices. One replay serves every use of a configuration's counts (the exhaustive
/// check prices each configuration and compares their counts from the same replay). Given update
/// prices it is untimed (untimed_replay, sim/simulator.h): each frame's update is predicted
/// from its counts. Without, the replay times its update and says so (`update_timed`).
struct CountingReplay {
    /// A measured frame that cast rays: its update (predicted, or timed) and the counted rays.
    struct Frame {
        double update_ns = 0, rays = 0;
        FrameObservation observation;  ///< observation_of the frame: what the coefficients price
    };
    std::vector<std::vector<Frame>> scenes;  ///< one entry per scene of the category, in its order
    ReplayCounts counts;                     ///< summed over every scene's measured frames
    bool update_timed = false;               ///< the replay timed each frame's update (no update prices)
};

struct StructureTuning {
    std::string structure;
    std::string mode;
    SearchResult search;
    std::vector<Candidate> candidates;                     ///< measured ones (defaults included)
    std::size_t best_candidate = 0;                        ///< lowest measured cost meeting the accuracy
    std::string prediction_model;                          ///< the calibration's chosen model, for predicted modes
    std::function<double(const nlohmann::json&)> predict;  ///< predicted modes: the model's cost of searched params
    std::size_t prediction_measurements = 0;               ///< timed configurations its calibration measured
    /// Eq. 5.4 for this structure on this category: the predicted modes' calibration, or in the
    /// measured mode a fit to the frames the search measured (counted by an untimed replay).
    /// What advise applies to an unseen scene's counters. None when no model could be fitted.
    std::optional<CostCoefficients> cost_model;
    /// The update's prices fitted beside it (UpdatePrices): what lets advise replay an unseen scene
    /// without timing its update. None where no plain update form was fitted.
    std::optional<UpdatePrices> update_model;
    double seconds = 0;
    std::size_t measurements = 0;  ///< simulator runs of the measured kind
    /// The ranked method's counting replays (the update timed), one per configuration of the space in its
    /// order (each on every scene of the category); empty where the search ran instead. The
    /// exhaustive check prices these rather than replaying the space again.
    std::vector<CountingReplay> space_replays;
    std::size_t refits = 0;  ///< timings after which the ranked method refitted its model
};

struct CategoryTuning {
    std::string category;
    std::vector<StructureTuning> structures;
    Candidate chosen;       ///< after the simplicity rule
    Candidate fastest;      ///< lowest measured cost over every structure
    std::string rule_note;  ///< empty, or why the simplicity rule chose another
};

/// The scene, generated or read once per process and reused by every evaluation.
const Recording& recording_of(const SceneSpec& scene);

/// Measures one configuration on a category: per scene the median per-frame total (update + ray
/// cast, eq. 5.5) over frames × repetitions, then the mean over the category's scenes. The mean,
/// not the median, because the cost to minimise is the time spent on the category: a setting that
/// is slow on one scene of three costs that time, and a median over scenes would ignore it.
///
/// With `verify`, the first repetition is also checked against the ground truth (untimed, so the
/// times are unchanged) and the accuracy filled in; without, only the level is known.
///
/// With `observations`, the first repetition's frames are appended as cost-model observations
/// (config_group `group` × 100 + the scene's index), their counters from an untimed replay.
MeasuredCost measure(const TuneCategory& category, const std::string& structure, const nlohmann::json& params,
                     std::uint32_t warmup_frames, std::uint32_t repetitions, bool verify = false,
                     std::vector<FrameObservation>* observations = nullptr, int group = 0);

/// Every configuration of `params` (complete) measured as measure() does, but repetition-major
/// by the planner `rcbench run` uses (runner/repetition_plan.h): repetition r of every
/// configuration before repetition r + 1 of any, so a burst of load on a shared machine spreads
/// over one repetition of many configurations (which their medians absorb) instead of falling on
/// every repetition of one. For exhaustive checks. With `observations`, entry i receives
/// configuration i's first repetition as measure() gives it.
std::vector<MeasuredCost> measure_interleaved(const TuneCategory& category, const std::string& structure,
                                              const std::vector<nlohmann::json>& params, std::uint32_t warmup_frames,
                                              std::uint32_t repetitions, bool verify = false,
                                              std::vector<std::vector<FrameObservation>>* observations = nullptr);

/// How many simulations the tuner's measuring paths have run in this process, by kind, one per
/// scene of a category: timed (their ray batches timed: measure, measure_interleaved) and
/// counting replays (no ray timed: predict_cost, the counters of an observed measurement), and of
/// those the replays that timed their update (no update prices). advise reports its budget from
/// its own calls; tests check it against these.
struct SimulationTally {
    std::uint64_t timed = 0, counting = 0, counting_update_timed = 0;
};
SimulationTally simulation_tally();

/// What the measured search minimises: the time per frame of a configuration that meets
/// `accuracy`, and far more (still ordered by time, so the search keeps its bearings) for one that
/// does not.
double constrained_cost(const MeasuredCost& cost, const AccuracyConstraint& accuracy);

/// The machine's calibration (runner/calibration.h, a structure at its defaults) and caches: the
/// priors of the tuner's fits. A structure's is measured the first time a fit asks for it, then
/// kept; one the micro-scenes cannot build has none.
class MachinePriors {
public:
    const ModelInputs& of(const std::string& structure);
    /// A structure's calibration given, not measured (a calibration at hand, or a test's).
    void set(const std::string& structure, ModelInputs inputs) { measured_[structure] = std::move(inputs); }

private:
    std::map<std::string, ModelInputs> measured_;
};

/// Eq. 5.4 fitted (analysis/cost_model.h) to measured frames of one structure, the ray-cast model
/// the fit chooses; nullopt when it chooses none (too few distinct configurations). The fit is
/// free of the calibration: its balance of C_RB and C_T ranks a map's configurations better than
/// the micro-scenes' in-cache values (docs/model.md). But a tuning measures a few configurations
/// of one category whose counters move together, and on a noisy machine the free fit may price
/// every ray's work at 0 and leave a start-up cost alone, which ranks nothing; then the fit is
/// made again with `priors()`, the structure's calibration (MachinePriors), and where that still
/// prices no ray work (nothing pinned), the calibration's own costs are the model; it says which.
/// With `update`, it receives the update's prices from the same fit (update_prices).
std::optional<CostCoefficients> fit_coefficients(const std::vector<FrameObservation>& frames,
                                                 const std::function<const ModelInputs&()>& priors = {},
                                                 std::optional<UpdatePrices>* update = nullptr);

/// The model the ranked method starts from: the micro-scene calibration of `structure` alone
/// (`priors`, measured once per process), so nothing of the space is timed for it. nullopt without
/// `priors`, where the micro-scenes cannot build the structure, or where its costs price no ray
/// work: then the measured mode searches instead.
std::optional<CostCoefficients> prior_coefficients(MachinePriors* priors, const std::string& structure);

/// The largest space the ranked method replays whole; a larger one is searched (search_levels).
inline constexpr std::size_t kRankedSpaceLimit = 1024;

/// Configurations timed before the ranked method refits its model on their frames: a tuning
/// file's smallest calibration.
inline constexpr std::size_t kMinRefitConfigurations = 3;

/// Untimed where `update` prices the update; else the replay times it (CountingReplay).
CountingReplay counting_replay(const TuneCategory& category, const std::string& structure,
                               const nlohmann::json& searched, std::uint32_t warmup_frames,
                               const UpdatePrices* update = nullptr);

/// `coefficients` applied to a replay: per frame its update time plus rays × the per-ray cost;
/// ms per frame, median over a scene's frames, mean over the scenes.
double replay_cost(const CostCoefficients& coefficients, const CountingReplay& replay);

/// The ranked method's refit: eq. 5.4 fitted to the timed configurations' `frames`
/// (fit_coefficients, with the structure's priors) and applied to every replay, in their order.
/// nullopt while fewer than kMinRefitConfigurations are timed or where the fit prices no ray work
/// (the ranking then keeps its model).
std::optional<std::vector<double>> refit_predictions(const std::vector<FrameObservation>& frames,
                                                     std::size_t timed_configurations,
                                                     const std::vector<CountingReplay>& replays, MachinePriors* priors,
                                                     const std::string& structure);

/// Every configuration of a space replayed once (counting_replay): priced by `coefficients`
/// (the ranked method's ranking; the exhaustive check's ranking and model column), and grouped
/// into structures in effect by the same replay's counts (equal counts: one structure in effect,
/// e.g. a hash grid of depth 0 whatever its capacity).
struct SpaceSurvey {
    std::vector<double> predicted;        ///< replay_cost of each configuration, in the space's order
    std::vector<std::size_t> class_of;    ///< equality_classes of the replays' counts
    std::vector<CountingReplay> replays;  ///< the replays themselves, for the ranked method's refits
};
/// `replay` is counting_replay bound to a category, structure and warm-up (tests inject another);
/// it is called once per configuration of `all`.
SpaceSurvey survey_space(const std::vector<nlohmann::json>& all, const CostCoefficients& coefficients,
                         const std::function<CountingReplay(const nlohmann::json&)>& replay);

/// The predicted cost of a configuration (searched parameters) on `category`: replay_cost of its
/// counting_replay. `counts`, when given, receives what the replay counted.
/// `update`: as counting_replay's.
double predict_cost(const CostCoefficients& coefficients, const TuneCategory& category, const std::string& structure,
                    const nlohmann::json& searched, std::uint32_t warmup_frames, ReplayCounts* counts = nullptr,
                    const UpdatePrices* update = nullptr);

/// The predicted mode's cost: eq. 5.4 fitted to `spec.calibration` measured points (the defaults
/// and seeded random points of the space), applied by predict_cost. `predict` refers to
/// `category`, which must outlive it.
struct Predictor {
    std::function<double(const nlohmann::json&)> predict;  ///< searched parameters → ms per frame
    CostCoefficients coefficients;
    std::optional<UpdatePrices> update;  ///< fitted beside the coefficients, where a plain form was
    std::string model;                   ///< the chosen model and its held-out error
    std::size_t measurements = 0;        ///< measured calibration points
};
Predictor calibrate_predictor(const TuneSpec& spec, const TuneCategory& category, const std::string& structure,
                              MachinePriors* priors = nullptr);

/// Spearman's rank correlation (ties get their mean rank); NaN for fewer than two pairs or a
/// constant side.
double spearman(const std::vector<double>& a, const std::vector<double>& b);

/// The candidates among `all` that meet `accuracy`, in their order.
std::vector<const Candidate*> meeting(const std::vector<const Candidate*>& all, const AccuracyConstraint& accuracy);

/// Tunes every structure of the spec on one category. Only candidates that meet the spec's
/// accuracy are chosen; a structure with none is left out of the result (rule_note names it), and
/// InputError when no candidate of the category meets it.
CategoryTuning tune_category(const TuneSpec& spec, const TuneCategory& category, MachinePriors* priors = nullptr);

/// Rank for the simplicity rule, lower is simpler: the registry entry's StructureInfo::simplicity,
/// its default for a structure this program does not know.
int structure_simplicity(const std::string& structure);

/// The simplicity rule: among measured candidates within `tolerance` (0.03: 3%) of the fastest,
/// the simplest (by structure_simplicity: UG, then HG, then others; then less memory). Returns its
/// index.
std::size_t simplest_within(const std::vector<const Candidate*>& candidates, double tolerance);

}  // namespace rcb
