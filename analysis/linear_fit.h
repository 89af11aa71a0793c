#pragma once
/// Non-negative linear least squares with Ceres: y ≈ Σ_j β_j x_j, every β_j ≥ 0 (costs cannot be
/// negative), residuals relative to y (per-ray costs span orders of magnitude across scenes, and a
/// 10% error matters as much on a small scene as on a large one), a Huber loss against outlier
/// frames, and 95% confidence intervals from Ceres' covariance scaled by the residual variance.
///
/// A fit reports when it cannot be trusted: a design whose columns are (nearly) collinear, too few
/// distinct configurations to separate the terms, or a coefficient whose interval spans zero. Those
/// are flagged, never printed as numbers that look sure.
///
/// Calibration priors: a term may carry a value measured on designed micro-scenes (runner/
/// calibration.h). It enters as one more residual, (β_j/μ_j − 1)/σ, and bounds β_j to
/// [μ_j/3, 3·μ_j]: where the run's data cannot tell collinear terms apart, the calibration
/// decides; where they can, the data do. The condition number is that of the design with the prior
/// rows, so a prior makes a collinear design identifiable and its absence is reported.

#include <cmath>
#include <string>
#include <vector>

namespace rcb {

struct LinearProblem {
    std::vector<std::string> terms;      ///< one name per column
    std::vector<std::vector<double>> x;  ///< rows of the design matrix
    std::vector<double> y;               ///< observations, > 0
    std::vector<int> group;              ///< the configuration each row came from (its error's unit)
    /// The scene family each row came from (scene_family, model_terms.h): the k-fold's unit, so a
    /// family's twins are always held out together. Empty: each configuration is its own family.
    std::vector<int> family;
    std::vector<double> prior;  ///< per term: calibration value (> 0), or NaN; empty: none
    double prior_sigma = 0.5;   ///< relative uncertainty of a prior

    bool has_prior(std::size_t j) const { return j < prior.size() && prior[j] > 0; }
    /// The rows at `rows`, with the same terms and priors.
    LinearProblem subset(const std::vector<std::size_t>& rows) const;
    /// The same rows without column `column` (its term and prior).
    LinearProblem without(std::size_t column) const;
};

/// A prior bounds its coefficient to [μ/kPriorRange, kPriorRange·μ].
inline constexpr double kPriorRange = 3.0;

struct Coefficient {
    std::string name;
    double value = 0;
    double ci_low = 0, ci_high = 0;  ///< 95% interval
    bool spans_zero = false;         ///< the interval includes 0: not distinguishable from no effect
    double prior = NAN;              ///< the calibration value it was drawn towards, if any
    bool at_bound = false;           ///< at μ/3 or 3μ: the run's data pull it beyond the calibration's range
};

struct LinearFit {
    std::vector<Coefficient> coefficients;
    std::size_t observations = 0;
    std::size_t groups = 0;        ///< distinct configurations
    double r2 = 0;                 ///< of the relative residuals' model, on the fitted data
    double rmse_relative = 0;      ///< root mean square relative error on the fitted data
    double condition_number = 0;   ///< of the column-scaled, weighted design
    bool ill_conditioned = false;  ///< collinear terms: coefficients not identifiable
    bool too_few_groups = false;   ///< fewer distinct configurations than terms + 1
    bool converged = false;
    std::string status() const;  ///< "ok", or what is wrong

    double predict(const std::vector<double>& row) const;
};

/// Condition numbers above this are "ill-conditioned" (the terms cannot be told apart).
inline constexpr double kIllConditioned = 1e3;

LinearFit fit_linear(const LinearProblem& p, double huber_delta = 0.1);

/// Held-out error by k-fold over scene families (never over cells or frames: a configuration's
/// twin cell in a sibling scene would otherwise be in the fit that predicts it): for each
/// configuration of a held-out family, the relative error of its predicted median frame against
/// its measured median frame; the mean over configurations. (Medians, because on a shared machine
/// a few frames disturbed by other processes would otherwise stand in for the model's error.)
/// k is capped by the number of families, so with k or fewer it is leave-one-family-out; NaN with
/// fewer than two. Families are dealt to folds in a fixed order, so the result is deterministic.
double cross_validated_error(const LinearProblem& p, int k = 5);
/// The fold of each row in cross_validated_error: families (configurations where the problem has
/// none) dealt to min(k, families) folds in ascending order; every row -1 with fewer than two.
std::vector<int> fold_of_rows(const LinearProblem& p, int k = 5);

}  // namespace rcb
