// Implicit differentiation of phi's sparse linear solve for libtorch's autograd.
//
// tch 0.22 has no Rust-side custom autograd Function, so this shim defines one in C++
// (`LinearSolve`) whose forward and backward call back into Rust for the host-side solves:
// forward solves A x = b, backward solves the adjoint system Aᵀ y = ∂L/∂x and returns y as
// ∂L/∂b (the matrix is a constant). The Rust side owns the matrix; the shim holds it through an
// opaque `context` pointer whose `drop` callback runs exactly once, when the last holder (the
// forward call, or the autograd graph node that keeps it for the backward pass) is destroyed.
// Tensors cross the boundary as tch's raw `torch::Tensor*` handles. No C++ exception escapes:
// every entry point catches and reports through a status code and an error message.

#include <ATen/ATen.h>
#include <torch/csrc/autograd/custom_function.h>

#include <cstdint>
#include <cstring>
#include <exception>
#include <string>
#include <vector>

extern "C" {
// Solves (transpose ? Aᵀ : A) X = B for `len` f32 values of B (row-major `[n]` or `[n, k]`),
// writing X to `out`. Returns 0 on success, else non-zero with a message in `error`.
typedef int32_t (*phi_solve_callback)(void* context, const float* rhs, float* out, int64_t len,
                                      int32_t transpose, char* error, size_t error_len);
// Releases `context`.
typedef void (*phi_drop_callback)(void* context);
}

namespace {

struct SolveContext : torch::CustomClassHolder {
  void* context;
  phi_solve_callback solve;
  phi_drop_callback drop;

  SolveContext(void* context, phi_solve_callback solve, phi_drop_callback drop)
      : context(context), solve(solve), drop(drop) {}
  SolveContext(const SolveContext&) = delete;
  SolveContext& operator=(const SolveContext&) = delete;
  ~SolveContext() override { drop(context); }
};

at::Tensor host_solve(const SolveContext& context, const at::Tensor& rhs, bool transpose) {
  at::Tensor host = rhs.detach().to(at::kCPU, at::kFloat).contiguous();
  at::Tensor out = at::empty_like(host);
  std::vector<char> error(1024, '\0');
  int32_t status = context.solve(context.context, host.data_ptr<float>(), out.data_ptr<float>(),
                                 host.numel(), transpose ? 1 : 0, error.data(), error.size());
  if (status != 0) {
    error.back() = '\0';
    throw std::runtime_error(std::string(transpose ? "phi: the adjoint linear solve failed: "
                                                   : "phi: the linear solve failed: ") +
                             error.data());
  }
  return out.to(rhs.device());
}

struct LinearSolve : public torch::autograd::Function<LinearSolve> {
  static at::Tensor forward(torch::autograd::AutogradContext* ctx, at::Tensor rhs,
                            c10::intrusive_ptr<SolveContext> context) {
    at::Tensor x = host_solve(*context, rhs, false);
    ctx->saved_data["context"] = c10::IValue::make_capsule(std::move(context));
    return x;
  }

  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    c10::intrusive_ptr<torch::CustomClassHolder> capsule = ctx->saved_data["context"].toCapsule();
    const auto* context = static_cast<const SolveContext*>(capsule.get());
    // One adjoint solve; nothing flows to the context argument.
    return {host_solve(*context, grads[0], true), at::Tensor()};
  }
};

void write_error(char* error, size_t error_len, const char* message) {
  if (error == nullptr || error_len == 0) return;
  std::strncpy(error, message, error_len - 1);
  error[error_len - 1] = '\0';
}

}  // namespace

extern "C" int32_t phi_tch_linear_solve(const at::Tensor* rhs, void* context,
                                        phi_solve_callback solve, phi_drop_callback drop,
                                        at::Tensor** out, char* error, size_t error_len) {
  c10::intrusive_ptr<SolveContext> holder;
  try {
    holder = c10::make_intrusive<SolveContext>(context, solve, drop);
  } catch (...) {
    drop(context);
    write_error(error, error_len, "phi: could not allocate the solve context");
    return 1;
  }
  try {
    at::Tensor result = LinearSolve::apply(*rhs, std::move(holder));
    *out = new at::Tensor(std::move(result));
    return 0;
  } catch (const std::exception& e) {
    write_error(error, error_len, e.what());
    return 1;
  } catch (...) {
    write_error(error, error_len, "phi: unknown C++ exception in the linear solve");
    return 1;
  }
}
