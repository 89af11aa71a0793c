#pragma once
/// What analysis/ and tuner/ store in the results database, as typed rows: the fits of the cost
/// model, its validations, the derived scene categories and the tuner's results (schema in
/// docs/database.md). Each write is one transaction that first deletes the rows it replaces, so
/// storing again the same thing leaves one copy. The measurements themselves are written by the
/// runner's ResultStore (runner/store.h); every read is in runner/results_reader.h.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace rcb {

class Database;

/// One coefficient of a fit (fit_coefficient); an interval bound is NULL where not finite.
struct StoredCoefficient {
    std::string name;
    double value = 0;
    std::optional<double> ci_low, ci_high;
    bool spans_zero = false;
};

/// One fitted candidate model of a structure (a fit row and its coefficients).
struct StoredFit {
    std::string structure, target, model;
    std::string terms;  ///< JSON array of term names
    std::int64_t observations = 0, configurations = 0;
    double r2 = 0, rmse_relative = 0, heldout_error = 0, condition_number = 0;
    std::string status;
    bool chosen = false;
    std::optional<double> loso_error;
    std::string notes;
    std::vector<StoredCoefficient> coefficients;
};

/// Replaces run `run`'s fits with `fits`, stamped now.
void write_fits(Database& db, std::int64_t run, const std::vector<StoredFit>& fits);

/// One structure's row of a validation (model_validation); a NULL error where not finite.
struct StoredValidation {
    std::string structure;
    std::int64_t cells = 0, unpredictable = 0, scenes = 0, outside_range = 0;
    /// frame_median, its low and high bound, frame_p90, low, high, then the same of raycast.
    std::vector<std::optional<double>> errors;
    std::string models;  ///< JSON: the models used per target
};

/// Which validation of run `run` a set of rows is: against training run `train_run_uuid` (named
/// `train`), split `split` (`splits`: JSON), with its bootstrap's resamples and seed.
struct ValidationKey {
    std::int64_t run = 0;
    std::string train, train_run_uuid, split, splits;
    std::int64_t resamples = 0, seed = 0;
};

/// Replaces the rows of validation `key` with `rows`, stamped now.
void write_validation(Database& db, const ValidationKey& key, const std::vector<StoredValidation>& rows);

/// A derived scene category (derived_category).
struct StoredCategory {
    std::string name;
    std::int64_t scenes = 0;
    std::string centroid;  ///< JSON array
};

/// A clustering of run `run`'s scenes (scene_clustering, derived_category, derived_category_scene).
struct StoredClustering {
    std::int64_t run = 0, seed = 0, k = 0;
    std::optional<double> silhouette;
    std::string clustering;  ///< JSON
    std::vector<StoredCategory> categories;
    std::vector<std::pair<std::int64_t, std::int64_t>> scene_category;  ///< (scene id, category index)
};

/// Replaces run `c.run`'s clustering with `c`, stamped now.
void write_clustering(Database& db, const StoredClustering& c);

/// One evaluation of a tuner's search (tuning_evaluation).
struct StoredEvaluation {
    std::string params;  ///< JSON
    double cost_ms = 0;
};

/// One structure's tuning of a category (a tuning row and its evaluations).
struct StoredTuning {
    std::string structure, mode, algorithm, git_commit, spec;
    std::int64_t evaluations = 0, measurements = 0;
    double seconds = 0;
    std::string stop_reason, on_bound, best_params;
    double best_measured_ms = 0, best_measured_mad = 0;
    std::optional<double> best_predicted_ms;
    std::string default_params;
    std::optional<double> default_measured_ms;
    bool chosen = false;
    std::string accuracy;
    std::vector<StoredEvaluation> evaluation;
    std::string evaluation_kind;  ///< "measured" or "predicted"
};

/// Replaces the tuning named `name` of `category` with `rows`, stamped now.
void write_tuning(Database& db, const std::string& name, const std::string& category,
                  const std::vector<StoredTuning>& rows);

}  // namespace rcb
