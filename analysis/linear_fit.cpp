#include "analysis/linear_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <utility>

#include "core/base/statistics.h"

namespace rcb {
namespace {

/// One observation: r = (x·β − y) / y, with its analytic Jacobian x / y.
class RelativeLinearResidual : public ceres::CostFunction {
public:
    RelativeLinearResidual(const std::vector<double>& x, double y) : x_(x), y_(y) {
        set_num_residuals(1);
        mutable_parameter_block_sizes()->push_back(int(x.size()));
    }
    bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
        double prediction = 0;
        for (std::size_t j = 0; j < x_.size(); ++j) prediction += x_[j] * parameters[0][j];
        residuals[0] = (prediction - y_) / y_;
        if (jacobians && jacobians[0])
            for (std::size_t j = 0; j < x_.size(); ++j) jacobians[0][j] = x_[j] / y_;
        return true;
    }

private:
    std::vector<double> x_;
    double y_;
};

/// A calibration prior: r = (γ / (s·μ) − 1) / σ on the scaled coefficient γ = β·s.
class PriorResidual : public ceres::CostFunction {
public:
    PriorResidual(std::size_t k, std::size_t j, double scaled_mu, double sigma)
        : k_(k), j_(j), mu_(scaled_mu), sigma_(sigma) {
        set_num_residuals(1);
        mutable_parameter_block_sizes()->push_back(int(k));
    }
    bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override {
        residuals[0] = (parameters[0][j_] / mu_ - 1) / sigma_;
        if (jacobians && jacobians[0])
            for (std::size_t j = 0; j < k_; ++j) jacobians[0][j] = j == j_ ? 1 / (mu_ * sigma_) : 0.0;
        return true;
    }

private:
    std::size_t k_, j_;
    double mu_, sigma_;
};

/// The condition number of `a` with its columns scaled to unit norm, so that units (ns against
/// counts) do not count as ill-conditioning; infinite where a column is 0 (a term that never
/// occurs cannot be fitted).
double column_scaled_condition(Eigen::MatrixXd a) {
    for (Eigen::Index j = 0; j < a.cols(); ++j) {
        const double norm = a.col(j).norm();
        if (norm == 0) return INFINITY;
        a.col(j) /= norm;
    }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a);
    const auto& s = svd.singularValues();
    return s(s.size() - 1) > 0 ? s(0) / s(s.size() - 1) : INFINITY;
}

double condition_number_of(const LinearProblem& p) {
    const std::size_t n = p.x.size(), k = p.terms.size();
    if (n == 0 || k == 0) return INFINITY;
    std::size_t priors = 0;
    for (std::size_t j = 0; j < k; ++j) priors += p.has_prior(j);
    Eigen::MatrixXd a = Eigen::MatrixXd::Zero(Eigen::Index(n + priors), Eigen::Index(k));
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < k; ++j) a(Eigen::Index(i), Eigen::Index(j)) = p.x[i][j] / p.y[i];
    // The prior rows, in the units of the data rows (a relative residual per row).
    for (std::size_t j = 0, r = n; j < k; ++j)
        if (p.has_prior(j)) a(Eigen::Index(r++), Eigen::Index(j)) = 1 / (p.prior[j] * p.prior_sigma);
    return column_scaled_condition(std::move(a));
}

}  // namespace

LinearProblem LinearProblem::subset(const std::vector<std::size_t>& rows) const {
    LinearProblem out;
    out.terms = terms;
    out.prior = prior;
    out.prior_sigma = prior_sigma;
    for (std::size_t i : rows) {
        out.x.push_back(x[i]);
        out.y.push_back(y[i]);
        out.group.push_back(group[i]);
        if (!family.empty()) out.family.push_back(family[i]);
    }
    return out;
}

LinearProblem LinearProblem::without(std::size_t column) const {
    LinearProblem out = *this;
    out.terms.erase(out.terms.begin() + std::ptrdiff_t(column));
    if (column < out.prior.size()) out.prior.erase(out.prior.begin() + std::ptrdiff_t(column));
    for (std::vector<double>& row : out.x) row.erase(row.begin() + std::ptrdiff_t(column));
    return out;
}

std::string LinearFit::status() const {
    if (!converged) return "did not converge";
    if (ill_conditioned) return "ill-conditioned (collinear terms)";
    if (too_few_groups) return "too few distinct configurations";
    return "ok";
}

double LinearFit::predict(const std::vector<double>& row) const {
    double y = 0;
    for (std::size_t j = 0; j < row.size() && j < coefficients.size(); ++j) y += row[j] * coefficients[j].value;
    return y;
}

namespace {

/// Each column's RMS of x_ij / y_i (1 for a column that is 0 throughout): the solver works on
/// γ_j = β_j·s_j over columns scaled to unit RMS, so it sees terms of one magnitude whatever their
/// units (a per-frame constant next to a per-object count) and converges in a few iterations.
std::vector<double> column_scales(const LinearProblem& p) {
    const std::size_t k = p.terms.size(), n = p.y.size();
    std::vector<double> scale(k, 1.0);
    for (std::size_t j = 0; j < k; ++j) {
        double sum = 0;
        for (std::size_t i = 0; i < n; ++i) sum += (p.x[i][j] / p.y[i]) * (p.x[i][j] / p.y[i]);
        if (sum > 0) scale[j] = std::sqrt(sum / double(n));
    }
    return scale;
}

/// The unconstrained least-squares solution in γ, clamped to the bounds (the solver must start
/// feasible: at least 0, inside a prior's range).
std::vector<double> starting_point(const LinearProblem& p, const std::vector<std::vector<double>>& xs,
                                   const std::vector<double>& scale) {
    const std::size_t k = p.terms.size(), n = p.y.size();
    std::vector<double> gamma(k, 0.0);
    Eigen::MatrixXd a(n, k);
    Eigen::VectorXd b = Eigen::VectorXd::Ones(Eigen::Index(n));
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < k; ++j) a(Eigen::Index(i), Eigen::Index(j)) = xs[i][j] / p.y[i];
    const Eigen::VectorXd start = a.completeOrthogonalDecomposition().solve(b);
    for (std::size_t j = 0; j < k; ++j)
        gamma[j] = std::isfinite(start(Eigen::Index(j))) ? std::max(0.0, start(Eigen::Index(j))) : 0.0;
    for (std::size_t j = 0; j < k; ++j)
        if (p.has_prior(j))
            gamma[j] = std::clamp(gamma[j], scale[j] * p.prior[j] / kPriorRange, scale[j] * p.prior[j] * kPriorRange);
    return gamma;
}

/// The Huber-weighted relative residuals of every row, the priors' residuals and the bounds, on
/// the parameter block `gamma` (which must outlive the problem).
void add_residuals(ceres::Problem& problem, const LinearProblem& p, const std::vector<std::vector<double>>& xs,
                   const std::vector<double>& scale, double huber_delta, std::vector<double>& gamma) {
    const std::size_t k = p.terms.size(), n = p.y.size();
    for (std::size_t i = 0; i < n; ++i)
        problem.AddResidualBlock(new RelativeLinearResidual(xs[i], p.y[i]), new ceres::HuberLoss(huber_delta),
                                 gamma.data());
    for (std::size_t j = 0; j < k; ++j) {
        if (p.has_prior(j)) {
            problem.AddResidualBlock(new PriorResidual(k, j, scale[j] * p.prior[j], p.prior_sigma), nullptr,
                                     gamma.data());
            problem.SetParameterLowerBound(gamma.data(), int(j), scale[j] * p.prior[j] / kPriorRange);
            problem.SetParameterUpperBound(gamma.data(), int(j), scale[j] * p.prior[j] * kPriorRange);
        } else {
            problem.SetParameterLowerBound(gamma.data(), int(j), 0.0);
        }
    }
}

bool solve(ceres::Problem& problem) {
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = 1000;
    options.function_tolerance = 1e-12;
    options.parameter_tolerance = 1e-12;
    options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    return summary.termination_type == ceres::CONVERGENCE;
}

/// R² (of the absolute residuals) and the RMS relative error on the fitted data; returns Σr² of
/// the relative residuals. A non-finite result marks the fit as not converged.
double set_quality(const LinearProblem& p, const std::vector<double>& beta, LinearFit& fit) {
    const std::size_t k = p.terms.size(), n = p.y.size();
    const double mean_y = std::accumulate(p.y.begin(), p.y.end(), 0.0) / double(n);
    double ss_res = 0, ss_abs = 0, ss_tot = 0;
    for (std::size_t i = 0; i < n; ++i) {
        double pred = 0;
        for (std::size_t j = 0; j < k; ++j) pred += p.x[i][j] * beta[j];
        const double r = (pred - p.y[i]) / p.y[i];
        ss_res += r * r;
        ss_abs += (pred - p.y[i]) * (pred - p.y[i]);
        ss_tot += (p.y[i] - mean_y) * (p.y[i] - mean_y);
    }
    fit.r2 = ss_tot > 0 ? 1 - ss_abs / ss_tot : 0;
    fit.rmse_relative = std::sqrt(ss_res / double(n));
    if (!std::isfinite(fit.r2) || !std::isfinite(fit.rmse_relative)) {
        fit.converged = false;
        if (std::isnan(fit.r2)) fit.r2 = 0;
        if (std::isnan(fit.rmse_relative)) fit.rmse_relative = INFINITY;
    }
    return ss_res;
}

/// Cov(β) (k × k, row-major) from Ceres' (JᵀJ)⁻¹ of the problem's block, which holds `gamma`
/// (the solution in γ): Cov(β_i, β_j) = Cov(γ_i, γ_j) / (s_i s_j). Empty when Ceres cannot give it.
std::vector<double> coefficient_covariance(ceres::Problem& problem, std::vector<double>& block,
                                           const std::vector<double>& gamma, const std::vector<double>& scale) {
    const std::size_t k = scale.size();
    std::vector<double> covariance(k * k, NAN);
    ceres::Covariance::Options copt;
    copt.algorithm_type = ceres::DENSE_SVD;
    copt.null_space_rank = -1;  // rank-deficient designs still give an answer; they are flagged apart
    ceres::Covariance cov(copt);
    const std::vector<double> solved = block;
    block = gamma;
    std::vector<std::pair<const double*, const double*>> blocks{{block.data(), block.data()}};
    const bool have =
        cov.Compute(blocks, &problem) && cov.GetCovarianceBlock(block.data(), block.data(), covariance.data());
    block = solved;
    for (std::size_t i = 0; i < k; ++i)
        for (std::size_t j = 0; j < k; ++j) covariance[i * k + j] /= scale[i] * scale[j];
    return have ? covariance : std::vector<double>{};
}

/// Each coefficient's value, 95% interval (the covariance scaled by the residual variance s²), and
/// where a prior drew it, whether it sits at the prior's bound.
void set_coefficients(const LinearProblem& p, const std::vector<double>& beta, const std::vector<double>& covariance,
                      double s2, LinearFit& fit) {
    const std::size_t k = p.terms.size();
    for (std::size_t j = 0; j < k; ++j) {
        Coefficient& c = fit.coefficients[j];
        c.value = beta[j];
        const double se = !covariance.empty() ? std::sqrt(std::max(0.0, covariance[j * k + j] * s2)) : NAN;
        c.ci_low = c.value - 1.96 * se;
        c.ci_high = c.value + 1.96 * se;
        c.spans_zero = !(c.ci_low > 0);  // NaN (no interval) counts as unsure too
        if (p.has_prior(j)) {
            c.prior = p.prior[j];
            c.at_bound =
                c.value <= p.prior[j] / kPriorRange * (1 + 1e-6) || c.value >= p.prior[j] * kPriorRange * (1 - 1e-6);
        }
    }
}

}  // namespace

LinearFit fit_linear(const LinearProblem& p, double huber_delta) {
    LinearFit fit;
    const std::size_t k = p.terms.size(), n = p.y.size();
    fit.observations = n;
    fit.groups = std::set<int>(p.group.begin(), p.group.end()).size();
    fit.coefficients.resize(k);
    for (std::size_t j = 0; j < k; ++j) fit.coefficients[j].name = p.terms[j];
    if (n == 0 || k == 0) return fit;

    // Solve for γ on scaled columns; β and its covariance are mapped back below.
    const std::vector<double> scale = column_scales(p);
    std::vector<std::vector<double>> xs(n, std::vector<double>(k));
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < k; ++j) xs[i][j] = p.x[i][j] / scale[j];
    std::vector<double> beta = starting_point(p, xs, scale);  // γ while solving
    ceres::Problem problem;
    add_residuals(problem, p, xs, scale, huber_delta, beta);
    fit.converged = solve(problem);
    std::vector<double> gamma = beta;
    for (std::size_t j = 0; j < k; ++j) beta[j] = gamma[j] / scale[j];
    for (std::size_t j = 0; j < k; ++j)  // absurd inputs (a count of 1e300): no estimate, and said so
        if (!std::isfinite(beta[j])) beta[j] = 0, gamma[j] = 0, fit.converged = false;

    const double ss_res = set_quality(p, beta, fit);
    fit.condition_number = condition_number_of(p);
    fit.ill_conditioned = !(fit.condition_number < kIllConditioned);
    fit.too_few_groups = fit.groups < k + 1;
    // 95% intervals: Ceres' (JᵀJ)⁻¹ scaled by the residual variance s² = Σr² / (n − k).
    const std::vector<double> covariance =
        !fit.ill_conditioned && n > k ? coefficient_covariance(problem, beta, gamma, scale) : std::vector<double>{};
    set_coefficients(p, beta, covariance, n > k ? ss_res / double(n - k) : NAN, fit);
    return fit;
}

std::vector<int> fold_of_rows(const LinearProblem& p, int k) {
    const std::vector<int>& unit = p.family.empty() ? p.group : p.family;
    std::vector<int> families(unit.begin(), unit.end());
    std::sort(families.begin(), families.end());
    families.erase(std::unique(families.begin(), families.end()), families.end());
    const int folds = std::min<int>(k, int(families.size()));
    std::vector<int> out(unit.size(), -1);
    if (folds < 2) return out;
    std::map<int, int> fold_of;
    for (std::size_t i = 0; i < families.size(); ++i) fold_of[families[i]] = int(i % std::size_t(folds));
    for (std::size_t i = 0; i < unit.size(); ++i) out[i] = fold_of[unit[i]];
    return out;
}

double cross_validated_error(const LinearProblem& p, int k) {
    const std::vector<int> fold = fold_of_rows(p, k);
    const int folds = fold.empty() ? 0 : *std::max_element(fold.begin(), fold.end()) + 1;
    if (folds < 2) return NAN;
    double error = 0;
    std::size_t count = 0;
    for (int f = 0; f < folds; ++f) {
        std::vector<std::size_t> test, rows;
        for (std::size_t i = 0; i < p.y.size(); ++i) (fold[i] == f ? test : rows).push_back(i);
        const LinearFit fit = fit_linear(p.subset(rows));
        // Per held-out configuration: its median frame, measured against predicted. Medians keep
        // a few frames disturbed by other processes from standing in for the model's error.
        std::map<int, std::pair<std::vector<double>, std::vector<double>>> by_group;
        for (std::size_t i : test) {
            by_group[p.group[i]].first.push_back(p.y[i]);
            by_group[p.group[i]].second.push_back(fit.predict(p.x[i]));
        }
        for (auto& [g, v] : by_group) {
            const double measured = median(v.first), predicted = median(v.second);
            error += std::abs(predicted - measured) / measured;
            ++count;
        }
    }
    return count ? error / double(count) : NAN;
}

}  // namespace rcb
