#pragma once
/// The cost model's terms in one table: every place that names a term (the fit's candidate forms,
/// the calibration's priors, the Table 6.3 analog, the stored coefficients, the tuner's
/// CostCoefficients, its JSON and predict_cost) reads it from here. A new term is one row of
/// cost_terms() plus the counter it multiplies (frame_counters(), a FrameObservation field and its
/// database column).
///
/// The thesis' model (§5.1, eq. 5.4) per ray: C = C_RB·(N_TP + N_FP) + C_T·N_T + C_PREP; rcbench
/// adds the narrow phase's C_RO·N_RO (eq. 5.3), unpredicted steps, lines fetched and reported
/// hits (docs/model.md). Updates per frame: per change, per object, per write, per unit of work.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace rcb {

struct CalibrationPoint;
struct Counters;
struct FrameResult;
struct Coefficient;

/// One measured frame with everything the models use.
struct FrameObservation {
    std::string structure, params, scene, category;  ///< category: "uniform", "irregular", …
    std::string ray_mix;                             ///< the scene's ray mode (spec `ray_mix`), "" where unknown
    int config_group = 0;                            ///< distinct (scene, structure, params)
    /// "" for a whole frame; the query kind of one kind's batch (analysis/query_kinds.h)
    std::string kind;
    double rays = 0, raycast_ns = 0, update_ns = 0;
    double n_t = 0, n_rb = 0, n_tp = 0;  ///< per ray
    double n_ro = 0;                     ///< narrow-phase shape tests per ray (0 below the shapes query level)
    double n_th = 0;                     ///< node boxes hit per ray (trees; 0 where not counted)
    double n_mp = 0;                     ///< steps a history predictor missed per ray (0 where not counted)
    double n_miss = 0;                   ///< lines a simulated private cache fetched per ray (0 where not counted)
    double inserts = 0, removes = 0, moves = 0, objects = 0;
    double writes = 0;  ///< cells, entries and nodes the frame's update wrote (0 where not counted)
    /// The update's work beyond its writes (Structure::update_work; 0 where the structure counts
    /// none, NaN where the run did not record it: a form that prices it is then not offered).
    double update_work = 0;
    double memory_mb = 0;
    /// Where the structure's working set (memory_mb) sits: 0 within the first data cache, 1 within
    /// the second, …, the number of recorded caches (at most 3) beyond the last one (memory).
    int memory_tier = 0;

    double frame_ns() const { return update_ns + raycast_ns; }
};

/// The family of a scene: the scenes that share its objects and differ only in how rays are cast
/// at them or how they are represented. A held-out test leaves a family out whole, in the outer
/// and the inner loop alike (analysis/validation.h, linear_fit.h): a twin left in the training set
/// would let a model be judged on a scene it has in effect seen. From the scene's name, split at
/// '-': a map's "-brushes" or "-triangles" suffix, and a model's "-instances", "-obbs" or
/// "-triangles" (scene import's --model-mode), are dropped (one map or model, several
/// representations), every segment that names a ray mode ("center", "dense", …) is dropped
/// ("irregular-center-2000" and "irregular-2000", "irreg-l-dense" and "irreg-l": one generator,
/// other rays), and so is a seed's "-s<N>" (another draw of the same generator's settings).
/// Object counts stay: the 2000- and 40000-object scenes of one generator are two families. A
/// name that is all ray modes is its own family.
std::string scene_family(const std::string& scene);

/// How a stored or simulated count becomes a FrameObservation field.
enum class CounterScale {
    per_ray,    ///< a frame's sum over its rays, divided by them (0 in a frame without rays)
    mebibytes,  ///< bytes, as MiB
    as_is,      ///< a per-frame count (changes) or the scene's objects
};

/// A stored or simulated count `raw` of a frame with `rays` rays, scaled as `scale` says.
double scaled_count(CounterScale scale, double raw, double rays);

/// A counter of a measured frame: where the database keeps it, where the simulator counts it and
/// where an observation holds it.
struct FrameCounter {
    const char* symbol;  ///< "N_RB"
    const char* column;  ///< its column in the observations' query (frame JOIN cell): "frame.n_rb"
    const char* alias;   ///< the query's name for it: "n_rb"
    CounterScale scale;
    double FrameObservation::*field;
    /// What a simulated frame counted besides its Counters (changes, memory); nullptr for the
    /// counting pass's counters (`counted`) and for the scene's objects, a property of the whole run.
    double (*simulated)(const FrameResult&);
    /// The calibration micro-scenes' per-ray count of it (runner/calibration.h), nullptr where they
    /// do not count it.
    double CalibrationPoint::*calibrated;
    /// The counting pass's counter of this name (accel/model/counter_fields.h, by `alias`), looked
    /// up once when the table is made; nullptr for the others.
    std::uint64_t Counters::*counted = nullptr;
};
const std::vector<FrameCounter>& frame_counters();

enum class Target { raycast, update };

/// What a candidate form does with a term that is 0 in every frame of a structure.
enum class WhenAbsent {
    keep,        ///< the column stays (a constant, or the working set)
    drop,        ///< left out of the form
    drop_named,  ///< left out and named in StructureModels::unused_terms (N_T of brute force)
};

/// Where a ray-cast term shows in the Table 6.3 analog (breakdown_columns).
enum class BreakdownShow {
    none,           ///< not shown
    product,        ///< C·N always
    where_priced,   ///< C·N and N, where some row's C·N > 0
    where_counted,  ///< C·N and N, where some row's N > 0
    value,          ///< the coefficient itself (a constant's term)
};

struct CostTerm {
    /// The coefficient's name: its fit column, its fit_coefficient.name, its JSON key in a tuning's
    /// cost_model.
    const char* name = "";
    Target target = Target::raycast;
    /// The counters it multiplies, summed (frame_counters() symbols); none: a constant 1.
    std::vector<const char*> counters = {};
    const char* unit = "";
    WhenAbsent when_absent = WhenAbsent::drop;
    /// The calibration pass measures it: its pinned value is the fit's prior (linear_fit.h).
    bool prior = false;
    /// With `prior`: a run's fit draws the term towards the calibration's value. False where the
    /// micro-scenes price it apart from another term (C_HIT beside C_RB) but not at what the run's
    /// scenes pay for it: the run's frames alone decide it.
    bool run_prior = true;
    /// A tuning's cost_model carries it (the tuner's predict_cost and advise apply it).
    bool in_tuning = false;
    /// In a tuning's JSON, absent reads as 0: tunings written before the term existed lack it.
    bool optional_in_json = false;
    /// A cost of the traversal's steps and tests: a tuner's fit that prices none of these prices
    /// no ray work and ranks nothing (fit_coefficients, tuner/tuning.h).
    bool traversal = false;
    BreakdownShow breakdown = BreakdownShow::none;
};
/// Every term, ray-cast ones first; find_term throws std::logic_error for an unknown name.
const std::vector<CostTerm>& cost_terms();
const CostTerm& find_term(std::string_view name);
const FrameCounter& find_counter(std::string_view symbol);
/// The term's value in a frame: its counters' sum, or 1 for a constant.
double term_value(const CostTerm& term, const FrameObservation& f);

/// A candidate model as data: its terms in column order. A form is fitted only where each of
/// `required` occurs in some frame and a split has at least two groups.
enum class Split {
    none,
    by_params,  ///< each configuration its own copy ("c_object {mode=\"rebuild\"}")
};
struct ModelForm {
    const char* name;
    Target target;
    std::vector<const char*> terms;
    std::vector<const char*> required = {};
    Split split = Split::none;
};
/// The candidates from the smallest to the largest, per target: selection keeps the first within
/// the tolerance of the best held-out error.
const std::vector<ModelForm>& model_forms();

/// The observation of a simulated frame (the tuner's measurements), counters from its counting pass.
FrameObservation observation_of(const FrameResult& frame, double objects);

/// A chosen ray-cast model's coefficients, one per term of cost_terms() `in_tuning`, 0 where the model
/// lacks it: machine costs that price another scene's counters (what advise and the tuner's
/// predicted mode do).
struct CostCoefficients {
    std::vector<double> values;  ///< in the order of tuning_terms()
    std::string model;           ///< the chosen model and its held-out error

    CostCoefficients();
    /// The coefficient of term `name`; std::logic_error for a term the tuning does not carry.
    double operator[](std::string_view name) const;
    double& operator[](std::string_view name);
    /// ns per ray: Σ C·(the term's value) over the frame's counters.
    double per_ray(const FrameObservation& f) const;
    /// From a fit's coefficients; a per-category model's term from `category` ("" for the first
    /// category listed).
    static CostCoefficients from_fit(const std::vector<Coefficient>& fitted, const std::string& category);

    nlohmann::json to_json() const;
    /// InputError "<where>: …" when a coefficient is missing (and not optional) or not a finite number.
    static CostCoefficients from_json(const nlohmann::json& j, const std::string& where);
};
/// The terms a CostCoefficients carries, in its order.
const std::vector<const CostTerm*>& tuning_terms();

/// The fitted value of `name` among `fitted` ("C_RB", or a per-category copy "C_RB[<category>]";
/// with `category` empty, the first copy); 0 when the model lacks it.
double fitted_value(const std::vector<Coefficient>& fitted, const std::string& name, const std::string& category);

}  // namespace rcb
