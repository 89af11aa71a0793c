#include "analysis/linear_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

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
    // Scale columns to unit norm so that units (ns vs counts) do not count as ill-conditioning.
    for (Eigen::Index j = 0; j < a.cols(); ++j) {
        const double norm = a.col(j).norm();
        if (norm == 0) return INFINITY;  // a term that never occurs cannot be fitted
        a.col(j) /= norm;
    }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a);
    const auto& s = svd.singularValues();
    return s(s.size() - 1) > 0 ? s(0) / s(s.size() - 1) : INFINITY;
}

double median_of(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
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
    }
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

LinearFit fit_linear(const LinearProblem& p, double huber_delta) {
    LinearFit fit;
    const std::size_t k = p.terms.size(), n = p.y.size();
    fit.observations = n;
    fit.groups = std::set<int>(p.group.begin(), p.group.end()).size();
    fit.coefficients.resize(k);
    for (std::size_t j = 0; j < k; ++j) fit.coefficients[j].name = p.terms[j];
    if (n == 0 || k == 0) return fit;

    // Solve for γ_j = β_j·s_j on columns scaled to unit RMS (x_ij / y_i / s_j): the solver then
    // sees terms of one magnitude whatever their units (a per-frame constant next to a per-object
    // count), and converges in a few iterations; β and its covariance are mapped back below.
    std::vector<double> scale(k, 1.0);
    for (std::size_t j = 0; j < k; ++j) {
        double sum = 0;
        for (std::size_t i = 0; i < n; ++i) sum += (p.x[i][j] / p.y[i]) * (p.x[i][j] / p.y[i]);
        if (sum > 0) scale[j] = std::sqrt(sum / double(n));
    }
    std::vector<std::vector<double>> xs(n, std::vector<double>(k));
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = 0; j < k; ++j) xs[i][j] = p.x[i][j] / scale[j];

    // Start from the unconstrained least-squares solution, clamped to the bounds.
    std::vector<double> beta(k, 0.0);  // γ while solving
    {
        Eigen::MatrixXd a(n, k);
        Eigen::VectorXd b = Eigen::VectorXd::Ones(Eigen::Index(n));
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t j = 0; j < k; ++j) a(Eigen::Index(i), Eigen::Index(j)) = xs[i][j] / p.y[i];
        const Eigen::VectorXd start = a.completeOrthogonalDecomposition().solve(b);
        for (std::size_t j = 0; j < k; ++j)
            beta[j] = std::isfinite(start(Eigen::Index(j))) ? std::max(0.0, start(Eigen::Index(j))) : 0.0;
        for (std::size_t j = 0; j < k; ++j)  // inside a prior's range (the solver must start feasible)
            if (p.has_prior(j))
                beta[j] = std::clamp(beta[j], scale[j] * p.prior[j] / kPriorRange, scale[j] * p.prior[j] * kPriorRange);
    }

    ceres::Problem problem;
    for (std::size_t i = 0; i < n; ++i)
        problem.AddResidualBlock(new RelativeLinearResidual(xs[i], p.y[i]), new ceres::HuberLoss(huber_delta),
                                 beta.data());
    for (std::size_t j = 0; j < k; ++j) {
        if (p.has_prior(j)) {
            problem.AddResidualBlock(new PriorResidual(k, j, scale[j] * p.prior[j], p.prior_sigma), nullptr,
                                     beta.data());
            problem.SetParameterLowerBound(beta.data(), int(j), scale[j] * p.prior[j] / kPriorRange);
            problem.SetParameterUpperBound(beta.data(), int(j), scale[j] * p.prior[j] * kPriorRange);
        } else {
            problem.SetParameterLowerBound(beta.data(), int(j), 0.0);
        }
    }
    ceres::Solver::Options options;
    options.linear_solver_type = ceres::DENSE_QR;
    options.max_num_iterations = 1000;
    options.function_tolerance = 1e-12;
    options.parameter_tolerance = 1e-12;
    options.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    fit.converged = summary.termination_type == ceres::CONVERGENCE;
    std::vector<double> gamma = beta;
    for (std::size_t j = 0; j < k; ++j) beta[j] = gamma[j] / scale[j];
    for (std::size_t j = 0; j < k; ++j)  // absurd inputs (a count of 1e300): no estimate, and said so
        if (!std::isfinite(beta[j])) beta[j] = 0, gamma[j] = 0, fit.converged = false;

    // Quality on the fitted data, in relative terms.
    double ss_res = 0, ss_tot = 0;
    for (std::size_t i = 0; i < n; ++i) {
        double pred = 0;
        for (std::size_t j = 0; j < k; ++j) pred += p.x[i][j] * beta[j];
        const double r = (pred - p.y[i]) / p.y[i];
        ss_res += r * r;
    }
    double mean_y = 0;
    for (double y : p.y) mean_y += y;
    mean_y /= double(n);
    double ss_abs = 0;
    for (std::size_t i = 0; i < n; ++i) {
        double pred = 0;
        for (std::size_t j = 0; j < k; ++j) pred += p.x[i][j] * beta[j];
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
    fit.condition_number = condition_number_of(p);
    fit.ill_conditioned = !(fit.condition_number < kIllConditioned);
    fit.too_few_groups = fit.groups < k + 1;

    // 95% intervals: Ceres' (JᵀJ)⁻¹ scaled by the residual variance s² = Σr² / (n − k).
    std::vector<double> covariance(k * k, NAN);
    bool have_covariance = false;
    if (!fit.ill_conditioned && n > k) {
        ceres::Covariance::Options copt;
        copt.algorithm_type = ceres::DENSE_SVD;
        copt.null_space_rank = -1;  // rank-deficient designs still give an answer; we flag them above
        ceres::Covariance cov(copt);
        // The problem's parameter block holds γ: restore it, then map Cov(γ) to Cov(β) = Cov(γ) / (s_i s_j).
        std::vector<double> solved = beta;
        beta = gamma;
        std::vector<std::pair<const double*, const double*>> blocks{{beta.data(), beta.data()}};
        if (cov.Compute(blocks, &problem))
            have_covariance = cov.GetCovarianceBlock(beta.data(), beta.data(), covariance.data());
        beta = solved;
        for (std::size_t i = 0; i < k; ++i)
            for (std::size_t j = 0; j < k; ++j) covariance[i * k + j] /= scale[i] * scale[j];
    }
    const double s2 = n > k ? ss_res / double(n - k) : NAN;
    for (std::size_t j = 0; j < k; ++j) {
        Coefficient& c = fit.coefficients[j];
        c.value = beta[j];
        const double se = have_covariance ? std::sqrt(std::max(0.0, covariance[j * k + j] * s2)) : NAN;
        c.ci_low = c.value - 1.96 * se;
        c.ci_high = c.value + 1.96 * se;
        c.spans_zero = !(c.ci_low > 0);  // NaN (no interval) counts as unsure too
        if (p.has_prior(j)) {
            c.prior = p.prior[j];
            c.at_bound =
                c.value <= p.prior[j] / kPriorRange * (1 + 1e-6) || c.value >= p.prior[j] * kPriorRange * (1 - 1e-6);
        }
    }
    return fit;
}

double cross_validated_error(const LinearProblem& p, int k) {
    std::vector<int> groups(p.group.begin(), p.group.end());
    std::sort(groups.begin(), groups.end());
    groups.erase(std::unique(groups.begin(), groups.end()), groups.end());
    const int folds = std::min<int>(k, int(groups.size()));
    if (folds < 2) return NAN;
    std::map<int, int> fold_of;
    for (std::size_t i = 0; i < groups.size(); ++i) fold_of[groups[i]] = int(i % std::size_t(folds));
    double error = 0;
    std::size_t count = 0;
    for (int f = 0; f < folds; ++f) {
        std::vector<std::size_t> test, rows;
        for (std::size_t i = 0; i < p.y.size(); ++i) (fold_of[p.group[i]] == f ? test : rows).push_back(i);
        const LinearFit fit = fit_linear(p.subset(rows));
        // Per held-out configuration: its median frame, measured against predicted. Medians keep
        // a few frames disturbed by other processes from standing in for the model's error.
        std::map<int, std::pair<std::vector<double>, std::vector<double>>> by_group;
        for (std::size_t i : test) {
            by_group[p.group[i]].first.push_back(p.y[i]);
            by_group[p.group[i]].second.push_back(fit.predict(p.x[i]));
        }
        for (auto& [g, v] : by_group) {
            const double measured = median_of(v.first), predicted = median_of(v.second);
            error += std::abs(predicted - measured) / measured;
            ++count;
        }
    }
    return count ? error / double(count) : NAN;
}

}  // namespace rcb
