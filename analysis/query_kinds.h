#pragma once
/// Query kinds in the cost model (docs/model.md, "Query kinds: one set of coefficients").
///
/// The coefficients of eq. 5.4 (thesis §5.1) are physical costs: C_PREP per ray, C_RB per
/// ray–box test, C_T per traversal step. A closest-hit or any-hit query does less work than an
/// all-hits one, but the work it does should cost the same: its time should follow from its own
/// counters with the coefficients fitted on the run. A frame with rays of several kinds casts and
/// counts each kind as a batch of its own (sim/simulator.h; database table frame_kind), so
/// each kind has a time and counters to check that against.
///
/// The check: the run's chosen models (fitted on whole frames) price each kind's batch from its
/// counters; per (scene × configuration × kind) cell the median predicted against the median
/// measured. And the kind-transfer split of `rcbench validate`: a model chosen and fitted on the
/// all-hits batches only predicts the closest and any batches, and back.

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "analysis/cost_model.h"
#include "analysis/validation.h"
#include "runner/results_reader.h"

namespace rcb {

/// The run's measured frames per query kind: a frame with frame_kind rows gives one observation per
/// kind (that batch's rays, ray-cast time and per-ray counters; the frame's changes, memory and
/// objects), a frame without gives itself as kind "all". Each (scene, configuration, kind) is its
/// own config_group, so validation cells are per kind. Same order as load_observations.
std::vector<FrameObservation> load_kind_observations(Database& db, std::int64_t run);

/// One (scene, configuration, kind) cell: medians over its measured frames (repetitions pooled).
struct KindCell {
    std::string structure, params, scene, kind;
    double rays = NAN;  ///< rays of the kind per frame
    double ns_per_query = NAN, predicted_ns_per_query = NAN;
    double raycast_ns = NAN, predicted_raycast_ns = NAN;  ///< the kind's batch per frame
    double error = NAN;  ///< |predicted − measured| / measured of the batch per frame; NaN without a model
};

/// Every (scene, configuration, kind) cell of `kind_frames` priced by `models` (their predict_ray:
/// the chosen ray-cast form and coefficients as fitted), in the order of first appearance.
std::vector<KindCell> kind_cells(const std::vector<StructureModels>& models,
                                 const std::vector<FrameObservation>& kind_frames);

/// Per structure and kind: the median over cells of KindCell::error (NaN when no cell had a model).
struct KindError {
    std::string structure, kind;
    std::size_t cells = 0;
    double median_error = NAN;
};
std::vector<KindError> kind_errors(const std::vector<KindCell>& cells);

/// Per structure and kind over every batch of `kind_frames`, priced by `models` as in kind_cells:
/// what `rcbench fit` prints beside its per-structure table.
struct KindSummary {
    std::string structure, kind;
    std::size_t batches = 0;              ///< the kind's measured batches (one per frame that asks for it)
    std::size_t cells = 0;                ///< their (scene × configuration) cells
    double ns_per_query = NAN;            ///< median over the batches of ray-cast time / rays
    double predicted_ns_per_query = NAN;  ///< median over the batches of predict_ray; NaN without a model
    double median_error = NAN;            ///< KindError::median_error: the median over cells of KindCell::error
};
std::vector<KindSummary> kind_summaries(const std::vector<StructureModels>& models,
                                        const std::vector<FrameObservation>& kind_frames);

inline constexpr const char* kKindTransferGroup = "kind-transfer";
/// The group of one kind's batches priced by a frozen model: "kind:closest".
inline constexpr const char* kKindGroupPrefix = "kind:";

/// A model chosen and fitted on another run's whole frames (`rcbench validate --test`) pricing the
/// batches of each kind of `kind_frames` (the test run's, load_kind_observations) from their own
/// counters: one group per kind present, in QueryKind order, named kKindGroupPrefix + kind, of one
/// split. Its cells are kind_cells' (predicted against measured ray-cast time of the batch per
/// frame), summarised per structure as every group is (median, p90, bootstrap over scenes). No
/// frame error, as in calibration-only: a kind's frame time would be its batch plus the whole
/// frame's update. A cell whose structure has no model in `models` is unpredictable.
std::vector<ValidationGroup> validate_frozen_kinds(const std::vector<StructureModels>& models,
                                                   const std::vector<FrameObservation>& kind_frames,
                                                   const BootstrapOptions& options);

/// With all-hits batches and others: "all -> closest", "all -> any" (each kind present) and
/// "closest+any -> all"; without all-hits batches but with closest and any: each predicting the
/// other; none when `kind_frames` hold one kind only (a run without query kinds).
std::vector<ValidationSplit> kind_transfer_splits(const std::vector<FrameObservation>& kind_frames);

}  // namespace rcb
