#include "insitu/fit/diagnose.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <optional>
#include <random>
#include <thread>

#include "fit/ceres_support.h"
#include "insitu/fit/effects.h"
#include "insitu/fit/model_fit.h"

namespace insitu::fit {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Regularised incomplete beta I_x(a, b) by its continued fraction (modified Lentz), for the
// F distribution's tail. Accurate to ~1e-12 for the degrees of freedom met here.
double BetaContinuedFraction(double a, double b, double x) {
  constexpr double kTiny = 1e-300;
  double c = 1.0, d = 1.0 - (a + b) * x / (a + 1.0);
  if (std::abs(d) < kTiny) d = kTiny;
  d = 1.0 / d;
  double h = d;
  for (int m = 1; m <= 500; ++m) {
    const double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((a + m2 - 1.0) * (a + m2));
    d = 1.0 + aa * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    h *= d * c;
    aa = -(a + m) * (a + b + m) * x / ((a + m2) * (a + m2 + 1.0));
    d = 1.0 + aa * d;
    if (std::abs(d) < kTiny) d = kTiny;
    c = 1.0 + aa / c;
    if (std::abs(c) < kTiny) c = kTiny;
    d = 1.0 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1.0) < 1e-14) break;
  }
  return h;
}

double RegularisedBeta(double a, double b, double x) {
  if (x <= 0.0) return 0.0;
  if (x >= 1.0) return 1.0;
  const double ln_front =
      std::lgamma(a + b) - std::lgamma(a) - std::lgamma(b) + a * std::log(x) + b * std::log1p(-x);
  if (x < (a + 1.0) / (a + b + 2.0)) return std::exp(ln_front) * BetaContinuedFraction(a, b, x) / a;
  return 1.0 - std::exp(ln_front) * BetaContinuedFraction(b, a, 1.0 - x) / b;
}

// P(F > f) for F(d1, d2).
double FTail(double f, double d1, double d2) {
  if (!(f > 0)) return 1.0;
  return RegularisedBeta(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f));
}

struct Model {
  std::vector<const Effect*> effects;
  Result<FitResult> fit = FailedPrecondition("not fitted");
};

// Held-out rms: each fold fitted without its points, then predicted.
// fn(0 .. n-1) on up to hardware_concurrency() threads (the effects' per-fit caches are
// thread_local). A measured reason: on a 4,225-node table the candidates' fits are most of a
// diagnosis, and two cores halve it.
void ParallelFor(int n, const std::function<void(int)>& fn) {
  const int workers =
      std::max(1, std::min<int>(n, static_cast<int>(std::thread::hardware_concurrency())));
  std::atomic<int> next{0};
  const auto work = [&] {
    for (int k = next++; k < n; k = next++) fn(k);
  };
  std::vector<std::thread> threads;
  for (int w = 1; w < workers; ++w) threads.emplace_back(work);
  work();
  for (std::thread& t : threads) t.join();
}

Result<double> CrossValidatedRms(const FieldData& data, const std::vector<const Effect*>& effects,
                                 const std::vector<int>& fold_of, int folds) {
  std::vector<std::vector<int>> train(folds), test(folds);
  for (int i = 0; i < static_cast<int>(fold_of.size()); ++i) {
    for (int f = 0; f < folds; ++f) (fold_of[i] == f ? test : train)[f].push_back(i);
  }
  // Each fold's fit from its own start (never from a fit that saw its held-out points).
  std::vector<std::optional<Result<FitResult>>> fits(folds);
  ParallelFor(folds, [&](int f) {
    if (!test[f].empty()) fits[f] = FitEffects(data, effects, train[f]);
  });
  double sum = 0.0;
  int count = 0;
  for (int f = 0; f < folds; ++f) {
    if (test[f].empty()) continue;
    const Result<FitResult>& fit = *fits[f];
    if (!fit.ok()) return fit.status();
    for (int i : test[f]) {
      sum += (data.points[i].meas - Predict(data.points[i], effects, fit->effects)).squaredNorm();
      ++count;
    }
  }
  if (count == 0) return FailedPrecondition("no held-out points");
  return std::sqrt(sum / count);
}

std::string Describe(const std::string& name) {
  static const std::map<std::string, std::string> kWords = {
      {"offset", "an offset of the field"},
      {"scale", "a scale error (focal length or galvo gain)"},
      {"rotation", "a rotation of the field"},
      {"skew", "non-orthogonal axes"},
      {"mirror_separation", "two-mirror pincushion"},
      {"lens_radial", "radial lens distortion"},
      {"head_distortion", "the head's distortion about its optical axis"},
      {"head_geometry", "the scan head's own geometry"},
      {"perspective", "a measuring camera not parallel to the field"},
      {"thermal_drift", "thermal drift"},
      {"tracking_lag", "galvo tracking lag"},
      {"focus_scale", "a scale change with focus"},
  };
  const auto it = kWords.find(name);
  return it == kWords.end() ? name : it->second;
}

// The report of an effect as it enters the model.
// The physical head (head_geometry) and the leading-order terms it holds: offset (its zero
// offsets), scale (its gains), skew (its axis tilts), mirror_separation (its two-mirror
// distortion) and lens_radial (its lens). A rotation stays apart: it is as often the measuring
// frame's as the head's.
constexpr const char* kHeadGeometry = "head_geometry";

bool IsHeadTerm(const std::string& name) {
  return name == "offset" || name == "scale" || name == "skew" || name == "mirror_separation" ||
         name == "lens_radial" || name == "head_distortion";
}
// The head's leading-order distortion: the pincushion, the lens's radial term, or both about
// one axis.
bool IsDistortionTerm(const std::string& name) {
  return name == "mirror_separation" || name == "lens_radial" || name == "head_distortion";
}
// head_distortion is mirror_separation and lens_radial about one axis: never beside them.
bool Excludes(const std::string& a, const std::string& b) {
  return a != b && IsDistortionTerm(a) && IsDistortionTerm(b) &&
         (a == "head_distortion" || b == "head_distortion");
}
// The head is tried once a distortion term shows it: a field that is only linear is never put
// on the head.
bool HasLeadingHeadTerm(const std::vector<const Effect*>& effects) {
  return std::any_of(effects.begin(), effects.end(),
                     [](const Effect* e) { return IsDistortionTerm(e->name()); });
}

EffectReport Entered(const Effect& e, double delta_bic, double cv_rms_mm) {
  EffectReport rep;
  rep.name = e.name();
  rep.meaning = e.meaning();
  rep.param_names = e.param_names();
  rep.delta_bic = delta_bic;
  rep.cv_rms_mm = cv_rms_mm;
  return rep;
}

}  // namespace

Status DiagnoseOptions::Validate() const {
  if (folds < 2) return InvalidArgument("folds must be >= 2");
  if (!(min_delta_bic >= 0)) return InvalidArgument("min_delta_bic must be >= 0");
  if (max_effects < 0) return InvalidArgument("max_effects must be >= 0");
  if (!(min_cv_improvement >= 0 && min_cv_improvement < 1)) {
    return InvalidArgument("min_cv_improvement must be in [0, 1)");
  }
  if (!(alpha > 0 && alpha < 1)) return InvalidArgument("alpha must be in (0, 1)");
  if (permutations < 19) return InvalidArgument("permutations must be >= 19");
  if (neighbours < 1) return InvalidArgument("neighbours must be >= 1");
  return Status::Ok();
}

Result<Diagnosis> Diagnose(const FieldData& input, const DiagnoseOptions& o) {
  INSITU_RETURN_IF_ERROR(o.Validate());
  // A table of moves: its reference row is the zero of the others, not a measurement. It is
  // left out of every fit and held-out error, and the reference's own measuring error, common
  // to every move, is a nuisance offset in every model (the nominal one too), never a cause.
  FieldData moves;
  const bool relative = input.reference >= 0;
  if (input.reference >= static_cast<int>(input.points.size())) {
    return InvalidArgument(input.origin + ": the reference row " + std::to_string(input.reference) +
                           " is not among its " + std::to_string(input.points.size()) + " rows");
  }
  if (relative) {
    moves.origin = input.origin;
    moves.has_z = input.has_z;
    moves.has_t = input.has_t;
    moves.has_v = input.has_v;
    for (size_t i = 0; i < input.points.size(); ++i) {
      if (static_cast<int>(i) != input.reference) moves.points.push_back(input.points[i]);
    }
  }
  const FieldData& data = relative ? moves : input;
  const int n = static_cast<int>(data.points.size());
  if (data.DistinctPositions() < 3) {
    return FailedPrecondition(data.origin + ": " + std::to_string(data.DistinctPositions()) +
                              " distinct commanded positions" +
                              (relative ? " besides the reference row" : "") +
                              "; a diagnosis needs at least 3");
  }
  Diagnosis d;
  d.origin = data.origin;
  d.n_points = n;
  const int m = 2 * n;

  // Folds: leave-one-out for small sets, else a seeded shuffle into k folds.
  const bool loo = n <= o.loo_max_points;
  const int folds = loo ? n : o.folds;
  std::vector<int> fold_of(n);
  {
    std::vector<int> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::mt19937_64 rng(o.seed);
    if (!loo) std::shuffle(order.begin(), order.end(), rng);
    for (int k = 0; k < n; ++k) fold_of[order[k]] = k % folds;
  }

  // Noise from replicates: pooled scatter about each group's mean, both axes.
  const auto groups = data.ReplicateGroups();
  double ss_pe = 0.0;
  int df_pe = 0;
  for (const auto& g : groups) {
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (int i : g) mean += data.points[i].meas;
    mean /= static_cast<double>(g.size());
    for (int i : g) ss_pe += (data.points[i].meas - mean).squaredNorm();
    df_pe += 2 * (static_cast<int>(g.size()) - 1);
  }
  d.noise_mm = df_pe > 0 ? std::sqrt(2.0 * ss_pe / df_pe) : kNaN;
  d.noise_source = df_pe > 0 ? "replicates" : "none";

  // The nominal model (with a table of moves, the reference's error).
  const auto library = EffectLibrary();
  std::vector<const Effect*> current;
  for (const auto& e : library) {
    if (relative && e->name() == "offset") current.push_back(e.get());
  }
  const size_t nuisance = current.size();  // current[0, nuisance): never causes
  auto fit = FitEffects(data, current);
  if (!fit.ok()) return fit.status();
  d.nominal_rms_mm = fit->rms_mm;
  INSITU_ASSIGN_OR_RETURN(d.nominal_cv_rms_mm, CrossValidatedRms(data, current, fold_of, folds));
  for (const FieldPoint& p : input.points) {
    d.residual_nominal.push_back(p.meas - Predict(p, current, fit->effects));
  }
  for (const Effect* e : current) d.effects.push_back(Entered(*e, 0.0, d.nominal_cv_rms_mm));
  double bic = Bic(fit->rss_mm2, m, fit->parameters);
  double cv = d.nominal_cv_rms_mm;
  FitResult best_fit = *fit;

  // Forward selection.
  const Effect* head = nullptr;
  for (const auto& e : library) {
    if (e->name() == kHeadGeometry) head = e.get();
  }
  // The model the head was last tried against: a model it lost to is not tried again.
  std::vector<const Effect*> head_tried_against;
  // The physical head in place of its leading-order terms, whenever selection has stopped with
  // them in the model and the model has changed since the head was last tried: true when it
  // took their place. Not tried while selection still adds terms: against a model not yet
  // complete the head wins with parameters that stand in for what has not entered and then
  // keeps it out, since it holds it (measured: an offset with a lens_radial off the axis, 50
  // trials of tests/fit/hidden_effect_test.cc's mixtures; tried after each entry, the head took
  // lens_radial's place before the offset had entered, at f = 24 m with c3 and c5 on their
  // bounds, and left 134 um held out where the two effects leave the noise).
  const auto try_head = [&]() -> bool {
    if (head == nullptr || !HasLeadingHeadTerm(current) || current == head_tried_against ||
        std::find(current.begin(), current.end(), head) != current.end()) {
      return false;
    }
    head_tried_against = current;
    {
      std::vector<const Effect*> trial;
      std::vector<EffectReport> reports;
      bool placed = false;
      for (size_t k = 0; k < current.size(); ++k) {
        if (k >= nuisance && IsHeadTerm(current[k]->name())) {
          if (!placed) {
            trial.push_back(head);
            reports.push_back({});
            placed = true;
          }
          continue;
        }
        trial.push_back(current[k]);
        reports.push_back(d.effects[k]);
      }
      FitOptions warm;
      for (const Effect* e : trial) {
        std::vector<double> start;
        for (size_t k = 0; k < current.size(); ++k) {
          if (current[k] == e) start = best_fit.effects[k].params;
        }
        warm.start.push_back(start);
      }
      auto r = FitEffects(data, trial, {}, warm);
      if (!r.ok()) {
        d.notes.push_back(std::string(kHeadGeometry) + ": " + r.status().message());
      } else {
        const double trial_bic = Bic(r->rss_mm2, m, r->parameters);
        auto trial_cv = CrossValidatedRms(data, trial, fold_of, folds);
        if (!trial_cv.ok()) {
          d.notes.push_back(std::string(kHeadGeometry) +
                            ": held-out fit: " + trial_cv.status().message());
        } else if (trial_bic < bic && *trial_cv <= cv) {
          for (size_t k = 0; k < trial.size(); ++k) {
            if (trial[k] == head) reports[k] = Entered(*head, trial_bic - bic, *trial_cv);
          }
          current = trial;
          d.effects = reports;
          bic = trial_bic;
          cv = *trial_cv;
          best_fit = *r;
          return true;
        } else {
          d.notes.push_back(std::string(kHeadGeometry) +
                            " in place of its leading-order terms: "
                            "BIC " +
                            std::to_string(trial_bic - bic) + ", held-out " +
                            std::to_string(*trial_cv) + " mm against " + std::to_string(cv) +
                            " mm: kept the leading-order terms");
        }
      }
    }
    return false;
  };
  // Forward selection of the library's terms; then the physical head in place of the
  // leading-order ones it holds, judged against the completed leading-order model (tried
  // earlier, its tilts would stand in for a rotation not yet entered), and if it takes their
  // place, selection goes on from there.
  // The model so far with `extra` beside it: its BIC and fit, or nothing when the fit fails.
  struct Extended {
    double bic;
    FitResult fit;
  };
  const auto fit_with = [&](std::initializer_list<const Effect*> extra,
                            const FitOptions& start) -> std::optional<Extended> {
    std::vector<const Effect*> trial = current;
    trial.insert(trial.end(), extra);
    auto r = FitEffects(data, trial, {}, start);
    if (!r.ok()) return std::nullopt;
    return Extended{Bic(r->rss_mm2, m, r->parameters), *r};
  };
  // Two effects entering together (a pair, or simpler effects in place of one).
  struct Pair {
    const Effect* a;
    const Effect* b;
    Extended model;
  };
  for (;;) {
    while (static_cast<int>(current.size() - nuisance) < o.max_effects) {
      // Every candidate fitted jointly with the model so far, best BIC first.
      struct Candidate {
        const Effect* effect;
        double bic;
        FitResult fit;
      };
      std::vector<Candidate> candidates;
      std::vector<const Effect*> tried;
      for (const auto& e : library) {
        if (!e->Applicable(data) || e.get() == head) continue;
        if (std::find(current.begin(), current.end(), e.get()) != current.end()) continue;
        // The head's own terms are not added beside it: it holds them.
        if (std::find(current.begin(), current.end(), head) != current.end() &&
            IsHeadTerm(e->name())) {
          continue;
        }
        if (std::any_of(current.begin(), current.end(),
                        [&](const Effect* c) { return Excludes(c->name(), e->name()); })) {
          continue;
        }
        const int params = best_fit.parameters + static_cast<int>(e->param_names().size());
        if (params + 1 > m) continue;  // too few points for this model
        tried.push_back(e.get());
      }
      // The candidates' fits are independent: spread over the cores. The model so far starts
      // where it was fitted; each candidate from its own start.
      FitOptions warm;
      for (const EffectFit& f : best_fit.effects) warm.start.push_back(f.params);
      std::vector<std::optional<Result<FitResult>>> fits(tried.size());
      ParallelFor(static_cast<int>(tried.size()), [&](int k) {
        std::vector<const Effect*> trial = current;
        trial.push_back(tried[k]);
        fits[k] = FitEffects(data, trial, {}, warm);
      });
      for (size_t k = 0; k < tried.size(); ++k) {
        const Result<FitResult>& r = *fits[k];
        if (!r.ok()) {
          d.notes.push_back(tried[k]->name() + ": " + r.status().message());
          continue;
        }
        candidates.push_back({tried[k], Bic(r->rss_mm2, m, r->parameters), *r});
      }
      std::sort(candidates.begin(), candidates.end(),
                [](const Candidate& a, const Candidate& b) { return a.bic < b.bic; });
      // The strongest candidate that the held-out points confirm enters; a candidate whose
      // held-out fits fail (a fold that cannot pin its parameters) gives way to the next.
      const Candidate* taken = nullptr;
      double taken_cv = cv;
      for (const Candidate& c : candidates) {
        if (bic - c.bic < o.min_delta_bic) break;
        std::vector<const Effect*> trial = current;
        trial.push_back(c.effect);
        auto trial_cv = CrossValidatedRms(data, trial, fold_of, folds);
        if (!trial_cv.ok()) {
          d.notes.push_back(c.effect->name() + ": held-out fit: " + trial_cv.status().message());
          continue;
        }
        if (!(*trial_cv < (1.0 - o.min_cv_improvement) * cv)) {
          d.notes.push_back(c.effect->name() + " lowers BIC by " + std::to_string(bic - c.bic) +
                            " but the held-out error only from " + std::to_string(cv) + " to " +
                            std::to_string(*trial_cv) + " mm: not a cause");
          continue;
        }
        taken = &c;
        taken_cv = *trial_cv;
        break;
      }
      if (taken != nullptr && static_cast<int>(current.size() - nuisance) + 2 <= o.max_effects) {
        // Occam: two simpler effects that hold no more parameters between them than the one
        // taken and fit better are the better account (a pincushion whose centre runs to the
        // field's edge imitates an offset and a skew: kappa (x - x0)(y - y0)^2 is a constant
        // and a shear there). They enter together if the held-out points confirm them.
        // (Tried only while a pair still fits under max_effects.)
        const size_t p_taken = taken->effect->param_names().size();
        std::optional<Pair> simpler;
        const size_t top = std::min<size_t>(candidates.size(), 6);
        for (size_t i = 0; i < top; ++i) {
          for (size_t j = i + 1; j < top; ++j) {
            const Effect* a = candidates[i].effect;
            const Effect* b = candidates[j].effect;
            if (a == taken->effect || b == taken->effect || Excludes(a->name(), b->name())) {
              continue;
            }
            if (a->param_names().size() + b->param_names().size() > p_taken) continue;
            // Better than the one taken, and strongly better than each of the two alone
            // (else one of them is a bystander fitted to noise).
            const std::optional<Extended> r = fit_with({a, b}, warm);
            if (r && r->bic < taken->bic &&
                r->bic + o.min_delta_bic <= std::min(candidates[i].bic, candidates[j].bic) &&
                (!simpler || r->bic < simpler->model.bic)) {
              simpler = Pair{a, b, *r};
            }
          }
        }
        // ... and better than the one taken with either of them beside it: else the one taken
        // is real and the pair only holds the effect that comes next (a pincushion with its
        // lens term, and a rotation).
        if (simpler) {
          int checked = 0;
          for (const Effect* e : {simpler->a, simpler->b}) {
            if (Excludes(e->name(), taken->effect->name())) continue;
            ++checked;
            const std::optional<Extended> r = fit_with({taken->effect, e}, warm);
            if (r && r->bic <= simpler->model.bic) simpler.reset();
            if (!simpler) break;
          }
          if (checked == 0) simpler.reset();  // nothing to hold the one taken against
        }
        if (simpler) {
          std::vector<const Effect*> trial = current;
          trial.push_back(simpler->a);
          trial.push_back(simpler->b);
          auto trial_cv = CrossValidatedRms(data, trial, fold_of, folds);
          if (trial_cv.ok() && *trial_cv <= taken_cv) {
            d.notes.push_back(simpler->a->name() + " and " + simpler->b->name() +
                              " together explain more than " + taken->effect->name() +
                              " with no more parameters: taken in its place");
            for (const Effect* e : {simpler->a, simpler->b}) {
              d.effects.push_back(Entered(*e, simpler->model.bic - bic, *trial_cv));
              current.push_back(e);
            }
            bic = simpler->model.bic;
            cv = *trial_cv;
            best_fit = simpler->model.fit;
            continue;
          }
        }
      }
      if (taken != nullptr) {
        d.effects.push_back(Entered(*taken->effect, taken->bic - bic, taken_cv));
        current.push_back(taken->effect);
        bic = taken->bic;
        cv = taken_cv;
        best_fit = taken->fit;
        continue;
      }
      // Two effects of similar size: neither alone removes much of what both do. Pairs of the
      // strongest candidates are tried jointly under the same tests (BIC, held-out error).
      if (static_cast<int>(current.size() - nuisance) + 2 > o.max_effects) break;
      const size_t top = std::min<size_t>(candidates.size(), 4);
      std::vector<Pair> pairs;
      for (size_t i = 0; i < top; ++i) {
        for (size_t j = i + 1; j < top; ++j) {
          const Effect* a = candidates[i].effect;
          const Effect* b = candidates[j].effect;
          if (Excludes(a->name(), b->name())) continue;
          const std::optional<Extended> r = fit_with({a, b}, FitOptions{});
          if (r) pairs.push_back({a, b, *r});
        }
      }
      std::sort(pairs.begin(), pairs.end(),
                [](const Pair& x, const Pair& y) { return x.model.bic < y.model.bic; });
      const Pair* pair = nullptr;
      double pair_cv = cv;
      for (const Pair& pr : pairs) {
        if (bic - pr.model.bic < 2 * o.min_delta_bic) break;
        std::vector<const Effect*> trial = current;
        trial.push_back(pr.a);
        trial.push_back(pr.b);
        auto trial_cv = CrossValidatedRms(data, trial, fold_of, folds);
        if (!trial_cv.ok() || !(*trial_cv < (1.0 - o.min_cv_improvement) * cv)) continue;
        pair = &pr;
        pair_cv = *trial_cv;
        break;
      }
      if (pair == nullptr) break;
      for (const Effect* e : {pair->a, pair->b}) {
        d.effects.push_back(Entered(*e, pair->model.bic - bic, pair_cv));  // BIC of the pair
        current.push_back(e);
      }
      bic = pair->model.bic;
      cv = pair_cv;
      best_fit = pair->model.fit;
    }
    // Nothing more enters (or the model is full): the head against the completed model, and if
    // it takes the leading-order terms' place, selection goes on from there (what it holds is
    // no longer a candidate; the terms it does not hold, perspective, rotation, are). It enters
    // at most once and is not tried twice against one model, so this ends.
    if (!try_head()) break;
  }
  // The extended model's parameters, from the final joint fit.
  for (size_t k = 0; k < d.effects.size(); ++k) {
    d.effects[k].params = best_fit.effects[k].params;
    d.effects[k].stderrs = best_fit.effects[k].stderrs;
  }
  d.effects.erase(d.effects.begin(), d.effects.begin() + static_cast<long>(nuisance));
  d.extended_rms_mm = best_fit.rms_mm;
  d.extended_cv_rms_mm = cv;
  d.gain = cv > 0 ? d.nominal_cv_rms_mm / cv : 1.0;
  for (const FieldPoint& p : input.points) {
    d.residual_extended.push_back(p.meas - Predict(p, current, best_fit.effects));
  }
  if (relative) {
    // The offset common to every move is the field's own displacement at the reference (which
    // every move is measured from) plus the reference's measuring error; that error alone is
    // how far the reference row sits off the fitted field.
    const Eigen::Vector2d e = d.residual_extended[input.reference];
    const EffectFit& offset = best_fit.effects[0];  // the nuisance, first in every model
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "a table of moves from line %d (commanded %.4g, %.4g mm): that row is their "
                  "zero, not a measurement, and left out; the offset common to every move (the "
                  "field at the reference and the reference's own error) is dx = %.4g +- %.2g, "
                  "dy = %.4g +- %.2g mm, of which the reference's error is %.4g, %.4g mm",
                  input.points[input.reference].line, input.points[input.reference].cmd.x(),
                  input.points[input.reference].cmd.y(), offset.params[0], offset.stderrs[0],
                  offset.params[1], offset.stderrs[1], e.x(), e.y());
    d.notes.push_back(buf);
  }
  // The residuals of the points fitted (without a table's reference row), for the tests below.
  std::vector<Eigen::Vector2d> fitted_residual;
  for (size_t i = 0; i < input.points.size(); ++i) {
    if (static_cast<int>(i) != input.reference) fitted_residual.push_back(d.residual_extended[i]);
  }
  // Strongest first: by the BIC drop at entry (forward selection already takes them so).
  for (const EffectReport& e : d.effects) d.cause.push_back(e.name);

  // Structure left over.
  const double rss = best_fit.rss_mm2;
  const int df_res = m - best_fit.parameters;
  if (df_pe >= 2 && df_res - df_pe >= 1 && ss_pe > 0) {
    const double ss_lof = std::max(0.0, rss - ss_pe);
    const int df_lof = df_res - df_pe;
    const double f = (ss_lof / df_lof) / (ss_pe / df_pe);
    d.unexplained_test = "lack_of_fit";
    d.unexplained_p = FTail(f, df_lof, df_pe);
  } else if (n >= 2 * (o.neighbours + 1)) {
    // Neighbouring residuals are related when an effect is left over: the summed dot product
    // of each residual with its nearest neighbours' (commanded positions), against the same
    // statistic for residuals shuffled among the points. Two-sided: a pattern sampled
    // coarsely (a ripple of 3 points per period) makes neighbours point opposite ways.
    std::vector<std::vector<int>> nn(n);
    for (int i = 0; i < n; ++i) {
      std::vector<std::pair<double, int>> dist;
      for (int j = 0; j < n; ++j) {
        if (j != i) dist.push_back({(data.points[j].cmd - data.points[i].cmd).squaredNorm(), j});
      }
      std::partial_sort(dist.begin(), dist.begin() + o.neighbours, dist.end());
      for (int k = 0; k < o.neighbours; ++k) nn[i].push_back(dist[k].second);
    }
    const auto statistic = [&](const std::vector<Eigen::Vector2d>& r) {
      double s = 0.0;
      for (int i = 0; i < n; ++i) {
        for (int j : nn[i]) s += r[i].dot(r[j]);
      }
      return s;
    };
    std::vector<Eigen::Vector2d> r = fitted_residual;
    const double s0 = statistic(r);
    std::mt19937_64 rng(o.seed ^ 0x5bd1e995ull);
    int above = 0;
    for (int k = 0; k < o.permutations; ++k) {
      std::shuffle(r.begin(), r.end(), rng);
      above += std::abs(statistic(r)) >= std::abs(s0);
    }
    d.unexplained_test = "spatial_correlation";
    d.unexplained_p = (1.0 + above) / (1.0 + o.permutations);
  }
  d.unexplained = d.unexplained_p < o.alpha;
  if (d.unexplained) {
    // Where: the commanded region holding the largest residuals (the top tenth).
    std::vector<int> idx(n);
    std::iota(idx.begin(), idx.end(), 0);
    std::sort(idx.begin(), idx.end(), [&](int a, int b) {
      return fitted_residual[a].squaredNorm() > fitted_residual[b].squaredNorm();
    });
    const int top = std::max(1, n / 10);
    Eigen::Vector2d lo = Eigen::Vector2d::Constant(1e300), hi = -lo;
    for (int k = 0; k < top; ++k) {
      lo = lo.cwiseMin(data.points[idx[k]].cmd);
      hi = hi.cwiseMax(data.points[idx[k]].cmd);
    }
    char buf[200];
    std::snprintf(
        buf, sizeof buf,
        "largest residuals (%.4f mm and below) at commanded x %.2f..%.2f, y %.2f..%.2f mm",
        fitted_residual[idx[0]].norm(), lo.x(), hi.x(), lo.y(), hi.y());
    d.unexplained_where = buf;
  }
  // Within noise from the start: nothing to name.
  if (std::isfinite(d.noise_mm) && d.nominal_rms_mm <= 1.5 * d.noise_mm) d.cause.clear();
  return d;
}

std::string Diagnosis::Summary() const {
  char buf[256];
  std::string s;
  std::snprintf(buf, sizeof buf, "the model misses %.4f mm RMS (held-out %.4f mm) over %d points",
                nominal_rms_mm, nominal_cv_rms_mm, n_points);
  s += buf;
  if (cause.empty()) {
    s += "; no cause: ";
    // "Within noise" only where the noise is known (replicates): a scatter without replicates
    // (a grid measured by hand) has no structure a test finds, which does not make it noise.
    if (unexplained) {
      s += "no effect of the library explains it";
    } else if (std::isfinite(noise_mm)) {
      s += "within noise";
    } else {
      s += "nothing named, and no structure found in what is left (no replicates: the noise "
           "level is not known)";
    }
  } else {
    s += "; cause: ";
    for (size_t k = 0; k < effects.size(); ++k) {
      if (k) s += ", ";
      s += Describe(effects[k].name) + " (" + effects[k].name;
      for (size_t j = 0; j < effects[k].params.size(); ++j) {
        // A parameter the data do not determine (its standard error undefined: e.g. the
        // mirror separation without points off the focal plane) is not quoted as a value.
        const bool known = j >= effects[k].stderrs.size() || !std::isnan(effects[k].stderrs[j]);
        if (known) {
          std::snprintf(buf, sizeof buf, "%s %s = %.4g", j ? "," : ":",
                        effects[k].param_names[j].c_str(), effects[k].params[j]);
        } else {
          std::snprintf(buf, sizeof buf, "%s %s not determined", j ? "," : ":",
                        effects[k].param_names[j].c_str());
        }
        s += buf;
      }
      s += ")";
    }
    std::snprintf(buf, sizeof buf, "; extended model %.1f um held-out; gain %.1fx",
                  extended_cv_rms_mm * 1e3, gain);
    s += buf;
  }
  if (std::isfinite(noise_mm)) {
    std::snprintf(buf, sizeof buf, "; noise %.1f um (replicates)", noise_mm * 1e3);
    s += buf;
  }
  if (unexplained) s += "; unexplained structure remains: " + unexplained_where;
  return s;
}

std::string Diagnosis::ToJson() const {
  nlohmann::json j;
  const auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(); };
  j["n_points"] = n_points;
  j["nominal"] = {{"rms_mm", nominal_rms_mm}, {"cv_rms_mm", nominal_cv_rms_mm}};
  j["effects"] = nlohmann::json::array();
  for (const EffectReport& e : effects) {
    nlohmann::json params, errs;
    for (size_t k = 0; k < e.param_names.size(); ++k) {
      params[e.param_names[k]] = k < e.params.size() ? num(e.params[k]) : nlohmann::json();
      errs[e.param_names[k]] = k < e.stderrs.size() ? num(e.stderrs[k]) : nlohmann::json();
    }
    j["effects"].push_back({{"name", e.name},
                            {"meaning", e.meaning},
                            {"params", params},
                            {"stderr", errs},
                            {"delta_bic", e.delta_bic},
                            {"cv_rms_mm", e.cv_rms_mm}});
  }
  j["cause"] = cause;
  j["extended"] = {{"rms_mm", extended_rms_mm}, {"cv_rms_mm", extended_cv_rms_mm}};
  j["gain"] = gain;
  j["noise_mm"] = num(noise_mm);
  j["noise_source"] = noise_source;
  j["unexplained"] = unexplained;
  j["unexplained_test"] = unexplained_test;
  j["unexplained_p"] = unexplained_p;
  if (unexplained) j["unexplained_where"] = unexplained_where;
  j["notes"] = notes;
  j["origin"] = origin;
  return j.dump(2);
}

}  // namespace insitu::fit
