#pragma once
/// The thesis' performance model fitted to measurements (§5.1, eq. 5.4 and 5.5).
///
/// Ray cast, per structure, per ray:   C = C_RB·N_RB + C_T·N_T + C_PREP      (N_RB = N_TP + N_FP)
/// Update, per structure, per frame:   U = c_ins·inserts + c_rem·removes + c_mov·moves
///                                         + c_obj·objects (rebuilding structures) + c_frame
///
/// Observations are the frames of a run (not warm-up): the timed batch's time over its rays
/// against the counting pass's mean counters. Nested candidate models are compared by held-out
/// error (k-fold over configurations) and the smallest within the tolerance of the best is kept:
/// model no more than the data needs.

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "analysis/linear_fit.h"
#include "runner/sqlite.h"

namespace rcb {

/// One measured frame with everything the models use.
struct FrameObservation {
    std::string structure, params, scene, category;  ///< category: "uniform", "irregular", …
    int config_group = 0;                            ///< distinct (scene, structure, params)
    double rays = 0, raycast_ns = 0, update_ns = 0;
    double n_t = 0, n_rb = 0, n_tp = 0;  ///< per ray
    double inserts = 0, removes = 0, moves = 0, objects = 0;
    double memory_mb = 0;
};

/// Frames of one run; `run` is a run id, or 0 for the newest run (of `experiment` if given).
std::int64_t resolve_run(Database& db, std::int64_t run, const std::string& experiment);
std::vector<FrameObservation> load_observations(Database& db, std::int64_t run);

struct CandidateModel {
    std::string name;    ///< e.g. "eq5.4", "no-prep", "per-category", "with-memory"
    std::string target;  ///< "raycast" or "update"
    LinearProblem problem;
    LinearFit fit;
    double heldout_error = 0;  ///< mean absolute relative error on held-out configurations
    bool chosen = false;
};

struct StructureModels {
    std::string structure;
    std::vector<std::string> unused_terms;  ///< terms that are always 0 for this structure (e.g. N_T of bf)
    std::vector<CandidateModel> raycast, update;
    const CandidateModel* chosen(const std::string& target) const;
};

/// Held-out errors within max(0.5 points, 5% of the best) count as "as good as the best".
inline constexpr double kSelectionTolerance = 0.05;
inline constexpr double kSelectionFloor = 0.005;

std::vector<StructureModels> fit_cost_models(const std::vector<FrameObservation>& frames);

/// Replaces the run's stored fits (schema: docs/database.md, tables fit and fit_coefficient).
void store_fits(Database& db, std::int64_t run, const std::vector<StructureModels>& models);

/// Thesis Table 6.3 analog: one row per (scene, configuration).
struct CostBreakdown {
    std::string scene, structure, params;
    double c_total = 0;                        ///< measured ns per ray (median over frames)
    double rb_term = 0, t_term = 0, prep = 0;  ///< C_RB·N_RB, C_T·N_T, C_PREP from the chosen model
    double n_tp = 0, n_fp = 0, n_t = 0;
    double c_rb = NAN, c_t = NAN;
};
std::vector<CostBreakdown> cost_breakdown(const std::vector<FrameObservation>& frames,
                                          const std::vector<StructureModels>& models);

/// The fit stage's entry point: the run's frames fitted per structure (fit_cost_models), the fits
/// stored in the database (store_fits), and the Table 6.3 analog.
struct RunFit {
    std::int64_t run = 0;
    std::size_t frames = 0;
    std::vector<StructureModels> models;
    std::vector<CostBreakdown> breakdown;
};
RunFit fit_run(Database& db, std::int64_t run);

/// The stored, chosen ray-cast coefficients of a structure for a run (for the tuner's predictions);
/// from a per-category model, those of `category` ("uniform", "irregular", …).
struct RaycastCoefficients {
    double c_rb = 0, c_t = 0, c_prep = 0;
    std::string model;
};
std::optional<RaycastCoefficients> stored_raycast_coefficients(Database& db, std::int64_t run,
                                                               const std::string& structure,
                                                               const std::string& category);

/// "uniform", "irregular", "import", "recording": the category of a scene from its stored spec.
std::string scene_category(const std::string& spec_json);

}  // namespace rcb
