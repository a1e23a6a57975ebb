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

// The 8 corners of a point's cell on one level: table rows (hash arithmetic modulo 2^32, as int32 tensors wrap) and
// trilinear weights, corner k = bit 0: x, 1: y, 2: z.
inline void corners(const uint32_t* c, const float* t, const uint32_t* m, uint32_t mask, int64_t offset,
                    int64_t* row, float* w) {
  const uint32_t hx[2] = {c[0] * m[0], (c[0] + 1) * m[0]}, hy[2] = {c[1] * m[1], (c[1] + 1) * m[1]},
                 hz[2] = {c[2] * m[2], (c[2] + 1) * m[2]};
  const float wx[2] = {1.0f - t[0], t[0]}, wy[2] = {1.0f - t[1], t[1]}, wz[2] = {1.0f - t[2], t[2]};
  for (int k = 0; k < 8; ++k) {
    const int bx = k & 1, by = (k >> 1) & 1, bz = (k >> 2) & 1;
    row[k] = offset + static_cast<int64_t>((hx[bx] ^ hy[by] ^ hz[bz]) & mask);
    w[k] = wx[bx] * wy[by] * wz[bz];
  }
}

struct Levels {  // the encoding's per-level constants (see HashGrid)
  const float* res;
  const int32_t *mask, *offset, *mult;
  int64_t L;
};

// Points [begin, end) forward. F: the feature count when known at compile time (2 by default: 2.5x faster than a
// loop bound read at run time), 0: any (Fd).
template <int F>
void forward_points(int64_t begin, int64_t end, const Levels& lv, const float* xp, const float* tp, int64_t Fd,
                    bool smooth, float* yp) {
  const int64_t nf = F > 0 ? F : Fd, L = lv.L;
  for (int64_t i = begin; i < end; ++i) {
    for (int64_t l = 0; l < L; ++l) {
      const uint32_t m[3] = {(uint32_t)lv.mult[3 * l], (uint32_t)lv.mult[3 * l + 1], (uint32_t)lv.mult[3 * l + 2]};
      uint32_t c[3];
      float t[3], w[8];
      int64_t row[8];
      cell_of(xp + 3 * i, lv.res[l], smooth, c, t);
      corners(c, t, m, (uint32_t)lv.mask[l], lv.offset[l], row, w);
      float* out = yp + (i * L + l) * nf;
      for (int64_t f = 0; f < nf; ++f) {
        float acc = 0.0f;
        for (int k = 0; k < 8; ++k) acc += w[k] * tp[row[k] * nf + f];
        out[f] = acc;
      }
    }
  }
}

// Level l's rows of the table gradient, from every point.
template <int F>
void backward_level(int64_t l, int64_t n, const Levels& lv, const float* xp, const float* gp, int64_t Fd,
                    bool smooth, float* out) {
  const int64_t nf = F > 0 ? F : Fd, L = lv.L;
  const uint32_t m[3] = {(uint32_t)lv.mult[3 * l], (uint32_t)lv.mult[3 * l + 1], (uint32_t)lv.mult[3 * l + 2]};
  for (int64_t i = 0; i < n; ++i) {
    uint32_t c[3];
    float t[3], w[8];
    int64_t row[8];
    cell_of(xp + 3 * i, lv.res[l], smooth, c, t);
    corners(c, t, m, (uint32_t)lv.mask[l], lv.offset[l], row, w);
    const float* g = gp + (i * L + l) * nf;
    for (int k = 0; k < 8; ++k)
      for (int64_t f = 0; f < nf; ++f) out[row[k] * nf + f] += w[k] * g[f];
  }
}

}  // namespace

torch::Tensor hash_forward(torch::Tensor x, torch::Tensor table, torch::Tensor res, torch::Tensor mask,
                           torch::Tensor offset, torch::Tensor mult, bool smooth) {
  const int64_t n = x.size(0), L = res.size(0), F = table.size(1);
  auto y = torch::empty({n, L * F}, x.options());
  const Levels lv{res.data_ptr<float>(), mask.data_ptr<int32_t>(), offset.data_ptr<int32_t>(),
                  mult.data_ptr<int32_t>(), L};
  const float *xp = x.data_ptr<float>(), *tp = table.data_ptr<float>();
  float* yp = y.data_ptr<float>();
  at::parallel_for(0, n, 512, [&](int64_t begin, int64_t end) {
    switch (F) {
      case 1: forward_points<1>(begin, end, lv, xp, tp, F, smooth, yp); break;
      case 2: forward_points<2>(begin, end, lv, xp, tp, F, smooth, yp); break;
      case 4: forward_points<4>(begin, end, lv, xp, tp, F, smooth, yp); break;
      default: forward_points<0>(begin, end, lv, xp, tp, F, smooth, yp);
    }
  });
  return y;
}

// Table gradient: levels own disjoint table rows, so one thread per level adds without atomics.
torch::Tensor hash_backward(torch::Tensor x, torch::Tensor grad_y, int64_t rows, torch::Tensor res,
                            torch::Tensor mask, torch::Tensor offset, torch::Tensor mult, bool smooth) {
  const int64_t n = x.size(0), L = res.size(0), F = grad_y.size(1) / L;
  auto grad = torch::zeros({rows, F}, x.options());
  const Levels lv{res.data_ptr<float>(), mask.data_ptr<int32_t>(), offset.data_ptr<int32_t>(),
                  mult.data_ptr<int32_t>(), L};
  const float *xp = x.data_ptr<float>(), *gp = grad_y.data_ptr<float>();
  float* out = grad.data_ptr<float>();
  at::parallel_for(0, L, 1, [&](int64_t lb, int64_t le) {
    for (int64_t l = lb; l < le; ++l) {
      switch (F) {
        case 1: backward_level<1>(l, n, lv, xp, gp, F, smooth, out); break;
        case 2: backward_level<2>(l, n, lv, xp, gp, F, smooth, out); break;
        case 4: backward_level<4>(l, n, lv, xp, gp, F, smooth, out); break;
        default: backward_level<0>(l, n, lv, xp, gp, F, smooth, out);
      }
    }
  });
  return grad;
}
