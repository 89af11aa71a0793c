#pragma once
/// Which structure to ship for a user's scene: every registered structure measured on it at its
/// tuned parameters (from a tuning result's category) or its defaults, fastest first. Without a
/// category the scene's features pick the tuning's nearest category (analysis/scene_categories.h).
///
/// A tuned structure's parameters for this scene come from one of two methods:
///   category  the category's tuned parameters as they are: the best for the category's scenes
///             on average, which an unseen scene of the same kind need not share (a map's best
///             grid density depends on where its walls fall on the lattice)
///   model     the category's cost model (eq. 5.4, fitted while tuning) applied to this scene's own
///             counters: counting replays of the tuning's space on the scene (its search, with the
///             tuning's budget or `replays` and its seed, from the category's parameters; a space
///             within the budget is replayed whole), ranked by predicted cost;
///             the `verify_top` best (one per structure in effect: equal counts are one structure)
///             are measured beside the category's parameters; from the fastest of them a measured
///             descent (one level of one parameter at a time, two where one finds nothing; at
///             most `refine` measurements)
///             corrects the model's misranked neighbours, and the fastest measured is advised
/// `auto` takes the model where the tuning holds one for the structure, else the category.
///
/// verify_top 0 is the pure model: nothing is timed on the scene. The replays are untimed where
/// the tuning holds the update's prices (UpdatePrices: the update predicted from each frame's
/// changes and writes; with a tuning without them the replays time the update, and the budget
/// says so), the predicted best is advised unmeasured, and every row is the model's prediction (a
/// structure without a cost model is listed unpriced and never recommended).

#include <cstdint>
#include <functional>
#include <iosfwd>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "analysis/scene_categories.h"
#include "core/scene/workload.h"
#include "tuner/advise_baselines.h"
#include "tuner/tuning.h"

namespace rcb {

struct StructureInfo;

/// How tuned parameters are chosen (--method): `auto` is `automatic`.
enum class AdviseMethod { automatic, category, model };

/// Parses --method's text once, where it enters: auto, category or model; InputError
/// "--method: expected auto, category or model, got …" otherwise.
AdviseMethod parse_advise_method(std::string_view text);

/// How one tuned structure's parameters were chosen for the scene.
enum class ParameterMethod { category, model };

/// "category" or "model", as advise --json writes it.
std::string_view method_name(ParameterMethod method);
/// Compares with that name (advise --json's "method"), so a choice reads like the JSON it writes.
inline bool operator==(ParameterMethod method, std::string_view name) { return method_name(method) == name; }
std::ostream& operator<<(std::ostream& out, ParameterMethod method);

struct AdviseOptions {
    std::string scene;            ///< a recording, or a boxes CSV (given 10 frames of 1% dynamics, 1000 centre rays)
    std::string tuning;           ///< a tuning result (tuning-<name>.json), or empty: defaults
    std::string category;         ///< its category; empty: the one nearest the scene's features
    std::string method = "auto";  ///< how tuned parameters are chosen: auto, category, model (parse_advise_method)
    /// Model method: its best configurations measured beside the category's (0: the pure model,
    /// nothing timed on the scene)
    std::uint32_t verify_top = 3;
    std::uint32_t refine = 6;  ///< model method: measurements of the descent from the fastest verified
    /// Model method: at most this many counting replays per tuned structure, a space no larger
    /// replayed whole; none: the tuning's search budget
    std::optional<std::size_t> replays;
    bool exhaustive = false;            ///< also measure every configuration of each tuned structure's space
    std::optional<std::uint64_t> seed;  ///< --exhaustive's random baseline; none: the tuning's search seed
    std::uint32_t repetitions = 3;      ///< measurements per structure
    std::uint32_t warmup = 1;           ///< frames left out of the medians
    /// What the recommendation must answer; one that allows inexact answers also measures every
    /// structure at the other query levels (candidates, shapes) and verifies every measurement.
    AccuracyConstraint accuracy;
    std::function<void(const std::string& structure)> progress;  ///< called as each structure starts
    /// Tests only: made-up times for every simulation of the scene (TuneCategory::timing); empty:
    /// the clock's.
    SimulationTiming timing;
};

struct AdviceRow {
    std::string structure, params;  ///< params as compact JSON
    /// Measured; or with `predicted`, its ms the model's prediction (update and ray cast not apart,
    /// NaN); ms ∞ where the pure model has no price for the structure (unpriced).
    MeasuredCost cost;
    bool tuned = false;
    bool meets = true;  ///< meets the accuracy constraint
    bool predicted = false;
    bool priced() const;
};

/// Which of a tuning's categories a scene resembles, and why.
struct CategoryChoice {
    std::string category;
    SceneFeatures features;  ///< the scene's
    CategoryMatch match;
    std::string explanation;  ///< explain_match's paragraph
};

/// One configuration the model method considered: predicted on the scene, measured if verified.
struct ModelCandidate {
    nlohmann::json searched;  ///< the searched parameters
    std::optional<double> predicted_ms;
    std::optional<MeasuredCost> measured;
    bool is_category = false;  ///< the category's tuned parameters
};

struct ModelRanking;

/// How a tuned structure's parameters were chosen for the scene, and why.
struct ParameterChoice {
    std::string structure;
    ParameterMethod method = ParameterMethod::category;
    std::string why;                               ///< one sentence: why this method
    nlohmann::json category_searched;              ///< the category's tuned values of the searched parameters
    nlohmann::json chosen_searched;                ///< what was advised
    std::vector<SearchDimension> space;            ///< the tuning's space (empty: an older tuning without one)
    std::string model;                             ///< the cost model applied (model method)
    std::size_t replays = 0, space_size = 0;       ///< counting replays of the scene (model method) and the space
    std::size_t refined = 0;                       ///< configurations the measured descent added (model method)
    std::optional<nlohmann::json> predicted_best;  ///< model method: the best prediction (--verify-top 0 --refine 0's)
    AdviseBudget budget;                           ///< what advise measured and replayed for this structure
    std::vector<ModelCandidate>
        candidates;       ///< model method: measured ones first, fastest first; then the rest by prediction
    std::string summary;  ///< one paragraph for the terminal
    /// Model method: the replays' ranking its measured steps started from (advise_on_table takes
    /// them again for --exhaustive).
    std::shared_ptr<const ModelRanking> ranking;
};

/// Every configuration of a tuned structure's space measured on the scene: where the advice stands.
/// The scene's best is the table's; every cost here is its re-measurement after the choices
/// (advise_baselines.h: independent scoring).
struct ExhaustiveAdvice {
    std::string structure;
    std::size_t configurations = 0;
    nlohmann::json best_searched, advised_searched, category_searched;
    double best_table_ms = 0;                             ///< the scene's best in the table it was found in
    double best_ms = 0, advised_ms = 0, category_ms = 0;  ///< re-measured after the choice
    std::size_t rescored = 0;                             ///< configurations the scoring pass re-measured
    AdviseBudget budget;                                  ///< advise's, which the baselines match
    std::vector<MethodOutcome> methods;  ///< advise, the pure model, the category's, the baselines (compare_methods)
    double advised_gap() const { return advised_ms / best_ms - 1; }
    double category_gap() const { return category_ms / best_ms - 1; }
};

/// One paragraph on what the scene asks per frame (scene_workload): the rays per frame and the
/// share of each query kind, the objects changed per frame (p50, p90) and how far a move goes
/// relative to the object's size; and how the advice weighs them: every cost advise ranks by is
/// the scene's own update plus ray cast per frame (measured on its frames, or predicted from
/// counting replays of the same frames), never the thesis' 1% of objects and 1000 rays, unless
/// the scene is a boxes CSV, which gets those (`csv`).
std::string workload_summary(const SceneWorkload& workload, bool csv);

struct Advice {
    SceneWorkload workload;                    ///< what the scene asks per frame
    std::string workload_text;                 ///< workload_summary's paragraph
    std::vector<AdviceRow> rows;               ///< fastest per frame first
    std::optional<std::size_t> recommended;    ///< the fastest row that meets the accuracy; none when none does
    std::optional<CategoryChoice> chosen;      ///< when the category came from the scene's features
    std::vector<ParameterChoice> parameters;   ///< per tuned structure, in registry order
    std::vector<ExhaustiveAdvice> exhaustive;  ///< with AdviseOptions::exhaustive, per tuned structure with a space
    std::uint64_t baseline_seed = 1;           ///< the random baseline's (--seed, else the tuning's search seed)
};

// The steps of advise, each callable and testable alone; advise() runs them in this order (parse,
// compute and report apart, as pbrt-v4 splits its builders and google/benchmark compare.py its
// report):
//   advise_scene, select_tuning      the scene as a one-scene category; the tuning's category
//   plan_parameters                  per structure its parameters and, tuned, the method and why
//   model method, per tuned structure:
//     rank_by_model                  the space replayed on the scene, priced by the category's model
//     verify_candidates              the best predictions (one per structure in effect) and the
//                                    category's parameters measured
//     refine_by_descent              the measured descent from the fastest measured (--refine)
//     order_candidates               measured first, fastest first; then by prediction
//   plan_rows, measure_rows          every structure at its parameters measured, ranked by rank_advice
//   compare_exhaustively             every configuration's measurement against the advice

/// What a tuning result holds for one structure of one category.
struct TunedStructure {
    nlohmann::json params;                  ///< the category's best, every parameter
    std::vector<SearchDimension> space;     ///< empty: a tuning written before spaces were recorded
    std::optional<CostCoefficients> model;  ///< none: no model could be fitted, or an older tuning
    std::optional<UpdatePrices> update;     ///< none: the replays time the update (an older tuning)

    /// The category's parameters with `searched` put in, completed (InputError naming `where`).
    nlohmann::json with(const StructureInfo& info, const nlohmann::json& searched, const std::string& where) const;
};

/// The scene as advise measures it: a category of one scene, named for the file (a boxes CSV is
/// imported with 10 frames of dynamics).
TuneCategory advise_scene(const std::string& scene);

/// The tuning's category for the scene and what it holds; without a tuning, none (defaults).
struct TuningSelection {
    std::string category;                         ///< empty without a tuning
    std::optional<CategoryChoice> chosen;         ///< when the scene's features chose the category
    std::map<std::string, TunedStructure> tuned;  ///< by structure
    std::size_t budget = 30;                      ///< the replays' budget: --replays, else the tuning's search budget
    std::uint64_t seed = 1;                       ///< the tuning's search seed
};

/// Reads options.tuning (InputError for a file that is not a tuning result, a missing category,
/// or no scene categories to choose one from); `scene` is advise_scene's.
TuningSelection select_tuning(const AdviseOptions& options, const TuneCategory& scene);

/// One registered structure and its complete parameters (the tuned, the model's choice, or defaults).
struct StructurePlan {
    const StructureInfo* info = nullptr;
    nlohmann::json params;
};

struct ParameterPlan {
    std::vector<StructurePlan> structures;  ///< every registered structure, in registry order
    std::vector<ParameterChoice> choices;   ///< per tuned structure: its method and why; chosen = category's
};

/// Every structure's parameters and method, checked before the first measurement: InputError
/// where `method` is model and a structure has no cost model and space, or `exhaustive` and no
/// space. `tuning` names the file in messages.
ParameterPlan plan_parameters(const TuningSelection& selection, AdviseMethod method, bool exhaustive,
                              const std::string& tuning);

/// A counting replay of searched parameters on the scene: the predicted ms per frame; `counts`
/// receives what it counted.
using ReplayPrediction = std::function<double(const nlohmann::json& searched, ReplayCounts& counts)>;
/// A measurement of searched parameters on the scene.
using SceneMeasurement = std::function<MeasuredCost(const nlohmann::json& searched)>;

/// Every counting replay made of one structure, by searched parameters.
struct ReplayLog {
    std::vector<std::pair<nlohmann::json, ReplayCounts>> entries;
    std::optional<ReplayCounts> find(const nlohmann::json& searched, const std::vector<SearchDimension>& space) const;
};

/// The model method's search: the tuning's space replayed on the scene (search_levels with the
/// tuning's budget and seed, from the category's parameters).
struct ModelRanking {
    SearchResult search;
    ReplayLog replays;
};
ModelRanking rank_by_model(const std::vector<SearchDimension>& space, const nlohmann::json& start, std::size_t budget,
                           std::uint64_t seed, const ReplayPrediction& predict);

/// Indices of `evaluations` by predicted cost, lowest first, ties in the order evaluated.
std::vector<std::size_t> prediction_order(const std::vector<Evaluation>& evaluations);

/// What the model method knows of one structure on the scene, step by step.
struct ModelEvidence {
    std::vector<ModelCandidate> candidates;
    ReplayLog replays;                                         ///< every counting replay so far
    std::vector<std::optional<ReplayCounts>> measured_counts;  ///< per measured structure in effect
    std::size_t refined = 0;                                   ///< measurements the descent added
};

/// Every replayed configuration as a candidate, by prediction; the `verify_top` best measured,
/// skipping those that count like one measured already (the same structure in effect); then,
/// unless verify_top is 0 (the pure model: nothing measured), the category's parameters measured
/// too (added when the search did not replay them).
ModelEvidence verify_candidates(const ModelRanking& ranking, const std::vector<SearchDimension>& space,
                                const nlohmann::json& category_searched, std::uint32_t verify_top,
                                const SceneMeasurement& measure);

/// Meeting the accuracy first, then the lower time per frame.
bool measured_faster(const MeasuredCost& a, const MeasuredCost& b, const AccuracyConstraint& accuracy);

/// The neighbours the descent tries from `from`: per dimension in the space's order, the level
/// `stride` up, then `stride` down (those that exist; a dimension `from` lacks or at a level not
/// in the space has none).
std::vector<nlohmann::json> descent_neighbours(const std::vector<SearchDimension>& space, const nlohmann::json& from,
                                               std::size_t stride);

struct DescentSettings {
    std::vector<SearchDimension> space;
    nlohmann::json category_searched;
    std::uint32_t refine = 6;  ///< measurements the descent may add
    AccuracyConstraint accuracy;
};

/// The model's error can rank a neighbour of the best below it, so a measured descent refines
/// the fastest measured candidate: neighbours one level away (descent_neighbours, stride 1),
/// where none is faster two levels away (past a bump: a map's walls can make a grid's cost rise
/// and fall again along one parameter), moving to the first faster one, until none is or
/// `refine` measurements are spent. A neighbour that counts like one measured already is that
/// structure again and is not measured; one not replayed yet is replayed first.
void refine_by_descent(ModelEvidence& evidence, const DescentSettings& settings, const ReplayPrediction& predict,
                       const SceneMeasurement& measure);

/// Measured first, fastest (meeting the accuracy) first; then the rest by prediction; stable.
void order_candidates(std::vector<ModelCandidate>& candidates, const AccuracyConstraint& accuracy);

/// advise's measured steps taken again from the same ranking (verify_candidates with
/// `verify_top`, refine_by_descent, order_candidates), each timing read from `table` (per
/// configuration of `configurations`) instead of measured: the choice advise makes on the
/// measurements the --exhaustive baselines choose by, so it meets the same noise as theirs
/// (advise_baselines.h). `timed` counts the distinct configurations it read. None when a step
/// asks for a configuration the table lacks (a category level the space does not hold).
std::optional<TableChoice> advise_on_table(const ModelRanking& ranking, const DescentSettings& settings,
                                           std::uint32_t verify_top, const std::vector<nlohmann::json>& configurations,
                                           const std::vector<MeasuredCost>& table, const ReplayPrediction& predict);

/// The rows to measure: every structure at its parameters; when `accuracy` allows inexact answers,
/// each one at the boxes level also at the candidates and shapes levels.
struct RowPlan {
    std::vector<AdviceRow> rows;         ///< costs not measured yet
    std::vector<nlohmann::json> params;  ///< each row's complete parameters
};
RowPlan plan_rows(const std::vector<StructurePlan>& structures, const std::vector<ParameterChoice>& choices,
                  const AccuracyConstraint& accuracy);

/// Measures each row (`measure(structure, params)`) unless the model method measured its
/// configuration already (that measurement is reused); `progress` as each measurement starts.
/// The pure model (advise with verify_top 0) measures none: predict_rows.
void measure_rows(RowPlan& plan, const std::vector<ParameterChoice>& choices,
                  const std::function<MeasuredCost(const std::string&, const nlohmann::json&)>& measure,
                  const std::function<void(const std::string&)>& progress);

/// The pure model's rows: a model-method structure's row at its advised configuration priced by
/// that configuration's prediction; every other row unpriced (AdviceRow). Nothing is measured.
void predict_rows(RowPlan& plan, const std::vector<ParameterChoice>& choices);

/// The scoring pass: the re-measurement of configurations (indices into the space's), in order.
using Rescore = std::function<std::vector<MeasuredCost>(const std::vector<std::size_t>& indices)>;

/// Where the advice stands among every configuration of the space measured on the scene
/// (`configurations` searched parameters and their `table`): configurations that fail the
/// accuracy priced out (constrained_cost), as tune --exhaustive does. Beside advise: the pure
/// model, the category's parameters and the baselines of the choice's budget (compare_methods, the
/// random one seeded by `seed`, their replays told by `class_of`), which choose on `table`, as
/// `on_table` (advise's steps taken on it, advise_on_table) did; the scene's best is the table's.
/// Then `rescore` re-measures every choice and the best once, after all of them are made, and
/// each is scored on that (advise_baselines.h).
ExhaustiveAdvice compare_exhaustively(const ParameterChoice& choice, const std::vector<nlohmann::json>& configurations,
                                      const std::vector<MeasuredCost>& table, const AccuracyConstraint& accuracy,
                                      const Rescore& rescore, std::uint64_t seed = 1,
                                      const std::vector<std::size_t>& class_of = {},
                                      const std::optional<TableChoice>& on_table = std::nullopt);

/// InputError for a missing scene, a method other than auto, category or model, --category or
/// --exhaustive without --tuning, a tuning file that is not a
/// tuning result or lacks the category (or, with no category, lacks scene categories: written by
/// an older rcbench), --method model where the tuning holds no cost model for a structure,
/// --exhaustive with a tuning that records no search space, or warm-up that leaves no frame.
Advice advise(const AdviseOptions& options);

/// Sorts `rows` fastest first, marks which meet `accuracy`, and returns the fastest that does.
std::optional<std::size_t> rank_advice(std::vector<AdviceRow>& rows, const AccuracyConstraint& accuracy);

/// The category of `tuning` (a tuning result file) nearest the scene's features.
CategoryChoice choose_category(const std::string& tuning, const nlohmann::json& tuning_json, const Recording& scene);

/// "density=4 max_depth=2": searched parameters as advise prints them (strings unquoted).
std::string searched_text(const nlohmann::json& searched);

/// The advice as one JSON object (advise --json): the category choice, the parameter choices,
/// the rows, the recommendation and the exhaustive check.
nlohmann::json advice_json(const Advice& advice, const AdviseOptions& options);

}  // namespace rcb
