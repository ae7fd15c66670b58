#include "insitu/fit/group_model.h"

#include <ceres/ceres.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numeric>
#include <random>

#include "fit/ceres_support.h"

namespace insitu::fit {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Where each group's parameters sit in theta, nuisance first, then the candidates.
struct Layout {
  std::vector<int> begin;  // group g: theta[begin[g] .. begin[g + 1])
  int total() const { return begin.back(); }
};

Layout MakeLayout(const std::vector<ParameterGroup>& all) {
  Layout l;
  l.begin.push_back(0);
  for (const ParameterGroup& g : all)
    l.begin.push_back(l.begin.back() + static_cast<int>(g.params.size()));
  return l;
}

// The fit works on z = theta / scale for the active parameters; the others stay 0.
constexpr double kStepZ = 1e-4;

class GroupCost : public ceres::CostFunction {
 public:
  GroupCost(const GroupModel& model, const std::vector<int>& use, std::vector<int> active,
            std::vector<double> scale, int total)
      : model_(model),
        use_(use),
        active_(std::move(active)),
        scale_(std::move(scale)),
        total_(total) {
    set_num_residuals(static_cast<int>(use_.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(active_.size()));
  }

  std::vector<double> Theta(const double* z) const {
    std::vector<double> theta(total_, 0.0);
    for (size_t k = 0; k < active_.size(); ++k) theta[active_[k]] = scale_[k] * z[k];
    return theta;
  }

  bool Evaluate(double const* const* z, double* residuals, double** jacobians) const override {
    std::vector<double> r;
    const std::vector<double> theta = Theta(z[0]);
    if (!model_.Residuals(theta, use_, &r)) return false;
    for (size_t i = 0; i < r.size(); ++i) {
      if (!std::isfinite(r[i])) return false;
      residuals[i] = r[i];
    }
    if (jacobians == nullptr || jacobians[0] == nullptr) return true;
    const int m = static_cast<int>(use_.size());
    const int p = static_cast<int>(active_.size());
    std::vector<double> plus, minus;
    for (int k = 0; k < p; ++k) {
      std::vector<double> t = theta;
      t[active_[k]] = theta[active_[k]] + scale_[k] * kStepZ;
      if (!model_.Residuals(t, use_, &plus)) return false;
      t[active_[k]] = theta[active_[k]] - scale_[k] * kStepZ;
      if (!model_.Residuals(t, use_, &minus)) return false;
      for (int i = 0; i < m; ++i) jacobians[0][i * p + k] = (plus[i] - minus[i]) / (2 * kStepZ);
    }
    return true;
  }

 private:
  const GroupModel& model_;
  const std::vector<int>& use_;
  std::vector<int> active_;
  std::vector<double> scale_;
  int total_;
};

struct GroupFit {
  std::vector<double> theta;  // all parameters (inactive 0)
  std::vector<double> se;     // standard errors, all parameters (inactive NaN)
  double rss = 0.0;
  int residuals = 0, parameters = 0;
};

Result<GroupFit> Fit(const GroupModel& model, const std::vector<ParameterGroup>& all,
                     const Layout& layout, const std::vector<int>& groups,
                     const std::vector<int>& use, int max_iterations) {
  std::vector<int> active;
  std::vector<double> scale;
  for (int g : groups) {
    for (int j = layout.begin[g]; j < layout.begin[g + 1]; ++j) {
      active.push_back(j);
      scale.push_back(all[g].scale[j - layout.begin[g]]);
    }
  }
  const int m = static_cast<int>(use.size());
  const int p = static_cast<int>(active.size());
  if (m < p + 1) {
    return FailedPrecondition(std::to_string(m) + " residuals cannot determine " +
                              std::to_string(p) + " parameters");
  }
  if (p == 0) {  // nothing to fit: the model as it is
    GroupFit f;
    f.theta.assign(layout.total(), 0.0);
    f.se.assign(layout.total(), kNaN);
    f.residuals = m;
    std::vector<double> r;
    if (!model.Residuals(f.theta, use, &r))
      return FailedPrecondition("the model cannot be evaluated");
    for (double v : r) f.rss += v * v;
    return f;
  }
  std::vector<double> z(p, 0.0);
  auto* cost = new GroupCost(model, use, active, scale, layout.total());
  ceres::Problem problem;
  problem.AddResidualBlock(cost, nullptr, z.data());
  ceres::Solver::Options so = PreciseLmOptions(max_iterations);
  so.function_tolerance = 1e-10;
  so.parameter_tolerance = 1e-10;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  if (summary.termination_type != ceres::CONVERGENCE) {
    return FailedPrecondition("did not converge: " + summary.BriefReport());
  }
  GroupFit f;
  f.theta = cost->Theta(z.data());
  f.se.assign(layout.total(), kNaN);
  f.residuals = m;
  f.parameters = p;
  std::vector<double> r(m);
  Eigen::MatrixXd jac(m, p);
  std::vector<double> jrow(static_cast<size_t>(m) * p);
  double* jp = jrow.data();
  const double* zp = z.data();
  if (!cost->Evaluate(&zp, r.data(), &jp))
    return FailedPrecondition("the fitted model cannot be evaluated");
  for (int i = 0; i < m; ++i) {
    f.rss += r[i] * r[i];
    for (int k = 0; k < p; ++k) jac(i, k) = jrow[static_cast<size_t>(i) * p + k];
  }
  if (p > 0) {
    const std::vector<double> se = StandardErrorsZ(jac, f.rss / std::max(1, m - p));
    for (int k = 0; k < p; ++k) f.se[active[k]] = scale[k] * se[k];
  }
  return f;
}

}  // namespace

Status GroupSelectionOptions::Validate() const {
  if (folds < 2) return InvalidArgument("folds must be >= 2, got " + std::to_string(folds));
  if (!(min_delta_bic >= 0)) return InvalidArgument("min_delta_bic must be >= 0");
  if (!(min_cv_improvement >= 0 && min_cv_improvement < 1)) {
    return InvalidArgument("min_cv_improvement must be in [0, 1)");
  }
  if (max_groups < 1) return InvalidArgument("max_groups must be >= 1");
  if (max_iterations < 1) return InvalidArgument("max_iterations must be >= 1");
  return Status::Ok();
}

Result<GroupDiagnosis> DiagnoseGroups(const GroupModel& model,
                                      const std::vector<ParameterGroup>& nuisance,
                                      const std::vector<ParameterGroup>& candidates,
                                      const GroupSelectionOptions& o) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  std::vector<ParameterGroup> all = nuisance;
  all.insert(all.end(), candidates.begin(), candidates.end());
  for (const ParameterGroup& g : all) {
    if (g.params.empty() || g.scale.size() != g.params.size()) {
      return InvalidArgument("group " + g.name + ": needs parameters, one scale each");
    }
    for (double s : g.scale) {
      if (!(s > 0) || !std::isfinite(s))
        return InvalidArgument("group " + g.name + ": scale must be > 0");
    }
  }
  const Layout layout = MakeLayout(all);
  const int n = model.units();
  std::vector<int> everything(n);
  std::iota(everything.begin(), everything.end(), 0);

  // Folds of whole keys, shuffled with the seed.
  std::map<int, int> key_fold;
  {
    std::vector<int> keys;
    for (int i = 0; i < n; ++i) keys.push_back(model.fold_key(i));
    std::sort(keys.begin(), keys.end());
    keys.erase(std::unique(keys.begin(), keys.end()), keys.end());
    std::mt19937_64 rng(o.seed);
    std::shuffle(keys.begin(), keys.end(), rng);
    for (size_t k = 0; k < keys.size(); ++k) key_fold[keys[k]] = static_cast<int>(k % o.folds);
  }
  // The held-out rms of the pool and of each channel (0 for a channel without units).
  const int channels = std::max(1, model.channels());
  struct HeldOut {
    double pool = 0.0;
    std::vector<double> channel;
  };
  const auto held_out_all = [&](const std::vector<int>& groups) -> Result<HeldOut> {
    double ss = 0.0;
    int count = 0;
    std::vector<double> ss_c(channels, 0.0);
    std::vector<int> count_c(channels, 0);
    for (int f = 0; f < o.folds; ++f) {
      std::vector<int> train, test;
      for (int i = 0; i < n; ++i) (key_fold[model.fold_key(i)] == f ? test : train).push_back(i);
      if (test.empty()) continue;
      INSITU_ASSIGN_OR_RETURN(GroupFit fit,
                              Fit(model, all, layout, groups, train, o.max_iterations));
      std::vector<double> r;
      if (!model.Residuals(fit.theta, test, &r))
        return FailedPrecondition("held-out units cannot be evaluated");
      for (size_t k = 0; k < r.size(); ++k) {
        ss += r[k] * r[k];
        const int c = std::clamp(model.channel(test[k]), 0, channels - 1);
        ss_c[c] += r[k] * r[k];
        ++count_c[c];
      }
      count += static_cast<int>(r.size());
    }
    if (count == 0) return FailedPrecondition("no held-out units");
    HeldOut h;
    h.pool = std::sqrt(ss / count);
    for (int c = 0; c < channels; ++c) {
      h.channel.push_back(count_c[c] > 0 ? std::sqrt(ss_c[c] / count_c[c]) : 0.0);
    }
    return h;
  };

  GroupDiagnosis d;
  d.units = n;
  std::vector<int> current;
  for (size_t g = 0; g < nuisance.size(); ++g) current.push_back(static_cast<int>(g));
  auto base = Fit(model, all, layout, current, everything, o.max_iterations);
  if (!base.ok()) return base.status().Prefixed("the model as calibrated");
  INSITU_ASSIGN_OR_RETURN(HeldOut cv_all, held_out_all(current));
  d.nominal_cv_rms = cv_all.pool;
  d.nominal_rms = std::sqrt(base->rss / n);
  GroupFit best = *base;
  double bic = Bic(best.rss, n, best.parameters);
  double cv = d.nominal_cv_rms;
  {
    std::vector<double> r;
    if (model.Residuals(best.theta, everything, &r)) d.residual_nominal = r;
  }
  std::vector<double> entered_bic, entered_cv;
  std::vector<int> entered;
  while (static_cast<int>(entered.size()) < o.max_groups) {
    struct Candidate {
      int group;
      double bic;
      GroupFit fit;
    };
    std::vector<Candidate> tried;
    for (size_t c = nuisance.size(); c < all.size(); ++c) {
      const int g = static_cast<int>(c);
      if (std::find(current.begin(), current.end(), g) != current.end()) continue;
      std::vector<int> trial = current;
      trial.push_back(g);
      auto f = Fit(model, all, layout, trial, everything, o.max_iterations);
      if (!f.ok()) {
        d.notes.push_back(all[g].name + ": " + f.status().message());
        continue;
      }
      tried.push_back({g, Bic(f->rss, n, f->parameters), *f});
    }
    std::sort(tried.begin(), tried.end(),
              [](const Candidate& a, const Candidate& b) { return a.bic < b.bic; });
    bool took = false;
    for (const Candidate& c : tried) {
      if (bic - c.bic < o.min_delta_bic) break;
      std::vector<int> trial = current;
      trial.push_back(c.group);
      auto trial_all = held_out_all(trial);
      if (!trial_all.ok()) {
        d.notes.push_back(all[c.group].name + ": held-out fit: " + trial_all.status().message());
        continue;
      }
      const double trial_cv = trial_all->pool;
      if (channels > 1) {
        // What the candidate does to each kind of observation, for whoever reads the notes.
        std::string note = all[c.group].name + ": held out by channel (mm)";
        for (int ch = 0; ch < channels; ++ch) {
          char b[64];
          std::snprintf(b, sizeof b, "%s %d: %.4f -> %.4f", ch ? "," : "", ch, cv_all.channel[ch],
                        trial_all->channel[ch]);
          note += b;
        }
        d.notes.push_back(note);
      }
      // The pool's held-out error lowered enough; or one channel's, the pool's not raised.
      bool lowers = trial_cv < (1.0 - o.min_cv_improvement) * cv;
      for (int ch = 0; ch < channels && !lowers && channels > 1; ++ch) {
        lowers = cv_all.channel[ch] > 0 &&
                 trial_all->channel[ch] < (1.0 - o.min_cv_improvement) * cv_all.channel[ch] &&
                 trial_cv < cv;
      }
      if (!lowers) {
        d.notes.push_back(all[c.group].name + " lowers BIC by " + std::to_string(bic - c.bic) +
                          " but the held-out error only from " + std::to_string(cv) + " to " +
                          std::to_string(trial_cv) + ": not a cause");
        continue;
      }
      entered.push_back(c.group);
      entered_bic.push_back(c.bic - bic);
      entered_cv.push_back(trial_cv);
      current = trial;
      bic = c.bic;
      cv = trial_cv;
      cv_all = *trial_all;
      best = c.fit;
      took = true;
      break;
    }
    if (!took) break;
  }
  const auto report = [&](int g) {
    GroupReport r;
    r.name = all[g].name;
    r.meaning = all[g].meaning;
    r.params = all[g].params;
    for (int j = layout.begin[g]; j < layout.begin[g + 1]; ++j) {
      r.values.push_back(best.theta[j]);
      r.stderrs.push_back(best.se[j]);
    }
    return r;
  };
  for (size_t g = 0; g < nuisance.size(); ++g) d.nuisance.push_back(report(static_cast<int>(g)));
  for (size_t k = 0; k < entered.size(); ++k) {
    GroupReport r = report(entered[k]);
    r.delta_bic = entered_bic[k];
    r.cv_rms = entered_cv[k];
    d.groups.push_back(r);
    d.cause.push_back(r.name);
  }
  d.extended_rms = std::sqrt(best.rss / n);
  d.extended_cv_rms = cv;
  d.gain = cv > 0 ? d.nominal_cv_rms / cv : 1.0;
  std::vector<double> r;
  if (model.Residuals(best.theta, everything, &r)) d.residual_extended = r;
  return d;
}

}  // namespace insitu::fit
