// The fused multiresolution hash encoding on the CPU (see nerif/encoders/hash_kernel.py): per point and level the
// cell, the 8 corners' hashes and weights, the gathers and the blend in one loop, without the tensor path's
// (N, L, 8) intermediates. Built once per machine with torch.utils.cpp_extension (g++, OpenMP).
#include <torch/extension.h>
#include <ATen/Parallel.h>
#include <cmath>
#include <cstdint>

namespace {

// The cell of one point on one level: lower corner and fractional position per axis (as the tensor path).
inline void cell_of(const float* p, float r, bool smooth, uint32_t* c, float* t) {
  for (int a = 0; a < 3; ++a) {
    float u = std::min(std::max((p[a] + 1.0f) * 0.5f, 0.0f), 1.0f);
    float pos = u * r;
    float cf = std::min(std::floor(pos), r - 1.0f);
    float ta = pos - cf;
    if (smooth) ta = ta * ta * (3.0f - 2.0f * ta);
    c[a] = static_cast<uint32_t>(static_cast<int32_t>(cf));
    t[a] = ta;
  }
}

// Corner k's table row and trilinear weight (hash arithmetic modulo 2^32, as int32 tensors wrap).
inline int64_t corner(int k, const uint32_t* c, const float* t, const uint32_t* m, uint32_t mask, int64_t offset,
                      float* w) {
  const int bx = k & 1, by = (k >> 1) & 1, bz = (k >> 2) & 1;
  uint32_t idx = ((c[0] + bx) * m[0]) ^ ((c[1] + by) * m[1]) ^ ((c[2] + bz) * m[2]);
  *w = (bx ? t[0] : 1.0f - t[0]) * (by ? t[1] : 1.0f - t[1]) * (bz ? t[2] : 1.0f - t[2]);
  return offset + static_cast<int64_t>(idx & mask);
}

}  // namespace

torch::Tensor hash_forward(torch::Tensor x, torch::Tensor table, torch::Tensor res, torch::Tensor mask,
                           torch::Tensor offset, torch::Tensor mult, bool smooth) {
  const int64_t n = x.size(0), L = res.size(0), F = table.size(1);
  auto y = torch::empty({n, L * F}, x.options());
  const float *xp = x.data_ptr<float>(), *tp = table.data_ptr<float>(), *rp = res.data_ptr<float>();
  const int32_t *mp = mask.data_ptr<int32_t>(), *op = offset.data_ptr<int32_t>(), *mu = mult.data_ptr<int32_t>();
  float* yp = y.data_ptr<float>();
  at::parallel_for(0, n, 512, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      for (int64_t l = 0; l < L; ++l) {
        uint32_t c[3], m[3] = {(uint32_t)mu[3 * l], (uint32_t)mu[3 * l + 1], (uint32_t)mu[3 * l + 2]};
        float t[3];
        cell_of(xp + 3 * i, rp[l], smooth, c, t);
        float* out = yp + i * L * F + l * F;
        for (int64_t f = 0; f < F; ++f) out[f] = 0.0f;
        for (int k = 0; k < 8; ++k) {
          float w;
          const int64_t row = corner(k, c, t, m, (uint32_t)mp[l], op[l], &w);
          for (int64_t f = 0; f < F; ++f) out[f] += w * tp[row * F + f];
        }
      }
    }
  });
  return y;
}

// Table gradient: levels own disjoint table rows, so one thread per level adds without atomics.
torch::Tensor hash_backward(torch::Tensor x, torch::Tensor grad_y, int64_t rows, torch::Tensor res,
                            torch::Tensor mask, torch::Tensor offset, torch::Tensor mult, bool smooth) {
  const int64_t n = x.size(0), L = res.size(0), F = grad_y.size(1) / L;
  auto grad = torch::zeros({rows, F}, x.options());
  const float *xp = x.data_ptr<float>(), *gp = grad_y.data_ptr<float>(), *rp = res.data_ptr<float>();
  const int32_t *mp = mask.data_ptr<int32_t>(), *op = offset.data_ptr<int32_t>(), *mu = mult.data_ptr<int32_t>();
  float* out = grad.data_ptr<float>();
  at::parallel_for(0, L, 1, [&](int64_t lb, int64_t le) {
    for (int64_t l = lb; l < le; ++l) {
      uint32_t m[3] = {(uint32_t)mu[3 * l], (uint32_t)mu[3 * l + 1], (uint32_t)mu[3 * l + 2]};
      for (int64_t i = 0; i < n; ++i) {
        uint32_t c[3];
        float t[3];
        cell_of(xp + 3 * i, rp[l], smooth, c, t);
        const float* g = gp + i * L * F + l * F;
        for (int k = 0; k < 8; ++k) {
          float w;
          const int64_t row = corner(k, c, t, m, (uint32_t)mp[l], op[l], &w);
          for (int64_t f = 0; f < F; ++f) out[row * F + f] += w * g[f];
        }
      }
    }
  });
  return grad;
}
