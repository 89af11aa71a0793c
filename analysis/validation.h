#pragma once
/// How well the cost model (thesis §5.1, eq. 5.4 and 5.5: time per frame = update + rays × C)
/// predicts frames it never saw, with nothing about them used to choose or fit it.
///
/// Nested splits: a split is data, a name and the frames to fit and to predict. In each split the
/// whole selection of analysis/cost_model.h (candidate form, dropped terms, configuration
/// columns, coefficients) runs on the train frames only, and the test frames are priced by the
/// model so chosen: leave one scene family out, leave one generator (scene category) out, leave
/// the largest scenes out, and ray-mode transfer. Inside each split the selection's own k-fold
/// holds families out too (linear_fit.h). The leave-one-family-out of `fit_cost_models` refits
/// only the coefficients of a model chosen on all families: the held-out family helped choose it.
///
/// Transfer: a model chosen and fitted on one run (all its scenes) prices every cell of another
/// run from that run's counters.
///
/// Errors are per (scene × configuration) cell: |median predicted − median measured| / measured,
/// of the time per frame and of the ray-cast time per frame, summarised per structure by their
/// median and 90th percentile with bootstrap 95% intervals over scenes. A cell the model cannot
/// price is a miss: an infinite error in the median and p90, and its share is reported.

#include <cmath>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "analysis/cost_model.h"
#include "core/base/statistics.h"
#include "runner/results_reader.h"

namespace rcb {

/// One split: the frames whose model is chosen and fitted and the frames it predicts, as indices
/// into a run's frames. `group` names the summary the split joins (every leave-one-scene-out fold
/// joins one); `name` the split itself (the scene left out, "dense -> center", …).
struct ValidationSplit {
    std::string group, name;
    std::vector<std::size_t> train, test;
};

/// Each scene family (scene_family, model_terms.h: a map's brushes and triangles, a generator's
/// ray-mode variants) left out in turn; none with one family.
std::vector<ValidationSplit> family_out_splits(const std::vector<FrameObservation>& frames);
/// Each scene category (its generator, "import", "recording") left out in turn; none with one category.
std::vector<ValidationSplit> generator_out_splits(const std::vector<FrameObservation>& frames);
/// The scenes of the most objects, with their families, predicted from the others; none when
/// every scene is among them.
std::vector<ValidationSplit> largest_out_splits(const std::vector<FrameObservation>& frames);
/// Per ray mode: fitted on it, the other modes predicted, and back (with two modes, the two
/// directions); none with one mode. This split keeps a family's other ray modes in the fit on
/// purpose: it asks whether a model moves to other rays on known objects, not to new scenes
/// (leave-one-family-out asks that).
std::vector<ValidationSplit> ray_mode_splits(const std::vector<FrameObservation>& frames);
/// All of the above, in that order.
std::vector<ValidationSplit> nested_splits(const std::vector<FrameObservation>& frames);

inline constexpr const char* kFamilyOutGroup = "leave-one-family-out";
inline constexpr const char* kTransferGroup = "transfer";

/// |predicted − measured| / measured; NaN without a finite prediction or a positive measurement.
double relative_error(double predicted, double measured);

/// One (scene, configuration) cell predicted: medians over its frames (repetitions pooled).
struct CellPrediction {
    std::string split, structure, scene, params;
    std::string raycast_model, update_model;  ///< the forms the predicting fit chose; "" without
    double frame_ns = NAN, predicted_frame_ns = NAN;
    double raycast_ns = NAN, predicted_raycast_ns = NAN;  ///< ray cast per frame (NaN: no rays)
    double frame_error = NAN, raycast_error = NAN;        ///< |predicted − measured| / measured
    /// The cell's counters beyond the range its model was fitted on (outside_trained_range,
    /// analysis/cost_model.h): "" within, or where nothing was fitted.
    std::string outside;
    /// The structure had a model and the model a column for the cell's category and configuration.
    /// (calibration alone prices the ray cast only: its frame error is NaN)
    bool predictable() const { return std::isfinite(predicted_frame_ns) || std::isfinite(predicted_raycast_ns); }
};

/// Every cell of `frames` priced by `models` (their frozen predictors); cells of a structure
/// without one are unpredictable.
std::vector<CellPrediction> predict_cells(const std::vector<StructureModels>& models,
                                          const std::vector<const FrameObservation*>& frames, const std::string& split);

/// One split: fit_cost_models on its train frames, its test cells predicted.
std::vector<CellPrediction> run_split(const std::vector<FrameObservation>& frames, const ValidationSplit& split,
                                      const ModelInputs& inputs);

struct BootstrapOptions {
    int resamples = 2000;
    std::uint64_t seed = 1;
};

/// An error's median and 90th percentile over cells (linear between order statistics), each with
/// the 2.5% and 97.5% quantiles of its value over scene resamples (NaN without resamples).
struct ErrorSummary {
    double median = NAN, median_low = NAN, median_high = NAN;
    double p90 = NAN, p90_low = NAN, p90_high = NAN;
};

struct StructureValidation {
    std::string structure;
    std::size_t cells = 0, unpredictable = 0, scenes = 0;
    /// Cells counted as misses: the unpredictable ones and those measured in a quantity (frame,
    /// ray cast) their model did not price. Their share is misses / cells.
    std::size_t misses = 0;
    std::size_t outside = 0;  ///< predictable cells priced beyond the range their model was fitted on
    ErrorSummary frame, raycast;
    /// How many splits chose each form ("eq5.4" → 5).
    std::map<std::string, int> raycast_models, update_models;
};

/// Per structure over `cells` (one group's), in structure order. A cell measured but not priced
/// counts as a miss (an infinite error) in the median and p90. `frames_priced` false: the method
/// prices the ray cast only (calibration alone), the frame error is NaN and no frame a miss.
std::vector<StructureValidation> summarize(const std::vector<CellPrediction>& cells, const BootstrapOptions& options,
                                           bool frames_priced = true);

/// One group's cells and their summaries.
struct ValidationGroup {
    std::string name;
    std::vector<std::string> splits;
    std::vector<CellPrediction> cells;
    std::vector<StructureValidation> structures;
};

/// The splits run and summarised by group, groups in the order of their first split.
std::vector<ValidationGroup> validate_nested(const std::vector<FrameObservation>& frames, const ModelInputs& inputs,
                                             const std::vector<ValidationSplit>& splits,
                                             const BootstrapOptions& options);

/// A run predicted by a model chosen and fitted on another run's frames.
struct TransferValidation {
    ValidationGroup group;                   ///< named kTransferGroup
    std::vector<std::string> unpredictable;  ///< structures of the test run the train run did not measure
};
/// `models`: the train run's, chosen and fitted (fit_cost_models on its frames), so that a caller
/// that prices more with them (the test run's query kinds) fits once.
TransferValidation validate_transfer(const std::vector<StructureModels>& models,
                                     const std::vector<FrameObservation>& test, const BootstrapOptions& options);

inline constexpr const char* kCalibrationGroup = "calibration-only";

/// Calibration alone: each cell's ray cast per frame priced by its run's micro-scene calibration
/// (runner/calibration.h: rays × (C_PREP + C_RB·N_RB + C_T·N_T + C_MP·N_MP + C_MISS·N_MISS), the
/// terms the micro-scenes fitted), nothing fitted on any experiment's frames. The calibration does not
/// measure updates, so the frame error is NaN; a structure without calibrated terms is
/// unpredictable.
ValidationGroup validate_calibration_only(const std::vector<FrameObservation>& frames, const ModelInputs& inputs,
                                          const BootstrapOptions& options);

/// Mean frame error of each (structure, scene) over the scene's predictable cells: the per-scene
/// view `fit` prints.
std::map<std::pair<std::string, std::string>, double> scene_frame_errors(const std::vector<CellPrediction>& cells);

/// Replaces the rows of (run, train run, group) in model_validation (docs/database.md): `run` is the
/// predicted run in `db`, `train_uuid` the run the model was chosen on (the same run for nested
/// splits), `train` how it was named ("A.db:3", or "nested").
void store_validation(Database& db, std::int64_t run, const std::string& train, const std::string& train_uuid,
                      const ValidationGroup& group, const BootstrapOptions& options);

/// The run's uuid (what identifies it across databases).
std::string run_uuid(Database& db, std::int64_t run);

/// JSON of a group: its splits, summaries and cells (NaN as null).
nlohmann::json validation_json(const ValidationGroup& group, bool with_cells);

}  // namespace rcb
