#include "autodiff/gradcheck.h"

#include <cmath>
#include <numeric>
#include <random>
#include <sstream>

namespace layersnet::ad {

namespace {

std::vector<Var<double>> make_vars(Tape<double>& tape, const std::vector<GradcheckInput>& inputs, double prefill) {
  std::vector<Var<double>> vars;
  for (const auto& in : inputs) {
    Var<double> v = in.needs_grad ? tape.leaf(in.value.data(), in.value.rows(), in.value.cols())
                                  : tape.constant(in.value.data(), in.value.rows(), in.value.cols());
    if (v.grad) std::fill_n(v.grad, v.size(), prefill);
    vars.push_back(v);
  }
  return vars;
}

// <R, f(inputs)> without recording.
double projected(const GradcheckFn& f, const std::vector<GradcheckInput>& inputs, const RowMat<double>& r,
                 RowMat<double>* output = nullptr) {
  Tape<double> tape;
  NoRecord<double> off(tape);
  auto vars = make_vars(tape, inputs, 0.0);
  Var<double> y = f(tape, vars);
  if (output) *output = y.val();
  return (y.val().array() * r.array()).sum();
}

bool all_finite(const Eigen::Ref<const RowMat<double>>& m) { return m.array().isFinite().all(); }

}  // namespace

GradcheckReport gradcheck(const GradcheckFn& f, const std::vector<GradcheckInput>& inputs,
                          const GradcheckOptions& opt) {
  GradcheckReport rep;
  std::ostringstream fail;
  int n_fail = 0;
  std::mt19937_64 rng(opt.seed);
  std::normal_distribution<double> normal;

  Tape<double> tape;
  auto vars = make_vars(tape, inputs, opt.prefill);
  Var<double> y = f(tape, vars);
  rep.output = y.val();
  for (const auto& node : tape.nodes()) rep.ops_seen.insert(node.op);
  if (!all_finite(rep.output)) rep.finite = false, fail << "non-finite output\n";

  RowMat<double> r(y.rows, y.cols);
  for (int64_t k = 0; k < r.size(); ++k) r.data()[k] = normal(rng);
  bool any_grad = false;
  for (const auto& in : inputs) any_grad |= in.needs_grad;
  if (any_grad && !y.grad && y.size() > 0) {
    rep.ok = false;
    rep.failures = "output has no gradient although an input needs one";
    return rep;
  }
  if (y.grad) y.grd() += r;
  tape.backward_seeded();

  RowMat<double> no_record_out;
  projected(f, inputs, r, &no_record_out);
  if (no_record_out.rows() != rep.output.rows() || no_record_out.cols() != rep.output.cols() ||
      !(no_record_out.array() == rep.output.array()).all()) {
    // NaN != NaN, so this also flags non-finite outputs; the message says which.
    if (rep.finite) fail << "no-record forward differs from recorded forward\n";
    rep.ok = false;
  }

  for (std::size_t i = 0; i < inputs.size(); ++i) {
    if (!inputs[i].needs_grad) {
      rep.gradients.emplace_back();
      continue;
    }
    RowMat<double> ad = vars[i].grd().array() - opt.prefill;
    rep.gradients.push_back(ad);
    if (!all_finite(ad)) rep.finite = false, fail << "non-finite gradient of input " << i << "\n";
    const int64_t n = ad.size();
    std::vector<int64_t> coords(static_cast<std::size_t>(n));
    std::iota(coords.begin(), coords.end(), 0);
    if (n > opt.max_coords) {
      std::shuffle(coords.begin(), coords.end(), rng);
      coords.resize(static_cast<std::size_t>(opt.max_coords));
    }
    for (int64_t c : coords) {
      auto plus = inputs, minus = inputs;
      plus[i].value.data()[c] += opt.eps;
      minus[i].value.data()[c] -= opt.eps;
      const double fd = (projected(f, plus, r) - projected(f, minus, r)) / (2 * opt.eps);
      const double a = ad.data()[c];
      const double err = std::abs(a - fd);
      ++rep.coords_checked;
      if (std::isfinite(err)) rep.max_abs_error = std::max(rep.max_abs_error, err);
      if (!(err <= opt.atol + opt.rtol * std::abs(fd))) {
        if (n_fail++ < 8) fail << "input " << i << " coord " << c << ": ad " << a << " fd " << fd << "\n";
      }
    }
  }
  if (n_fail > 8) fail << "... " << n_fail << " coordinates failed in all\n";
  rep.failures = fail.str();
  rep.ok = rep.ok && rep.finite && n_fail == 0;
  return rep;
}

DirectionalReport directional_gradcheck(const GradcheckFn& f, const std::vector<GradcheckInput>& inputs,
                                        const GradcheckOptions& opt) {
  std::mt19937_64 rng(opt.seed);
  std::normal_distribution<double> normal;
  Tape<double> tape;
  auto vars = make_vars(tape, inputs, 0.0);
  Var<double> loss = f(tape, vars);
  LAYERSNET_CHECK(loss.rows == 1 && loss.cols == 1, "directional_gradcheck needs a 1x1 loss");
  tape.backward(loss);

  DirectionalReport rep;
  auto plus = inputs, minus = inputs;
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    if (!inputs[i].needs_grad) continue;
    for (int64_t c = 0; c < inputs[i].value.size(); ++c) {
      const double d = normal(rng);
      rep.analytic += vars[i].grad[c] * d;
      plus[i].value.data()[c] += opt.eps * d;
      minus[i].value.data()[c] -= opt.eps * d;
    }
  }
  const RowMat<double> one = RowMat<double>::Ones(1, 1);
  rep.numeric = (projected(f, plus, one) - projected(f, minus, one)) / (2 * opt.eps);
  rep.ok = std::abs(rep.analytic - rep.numeric) <= opt.atol + opt.rtol * std::abs(rep.numeric);
  return rep;
}

}  // namespace layersnet::ad
