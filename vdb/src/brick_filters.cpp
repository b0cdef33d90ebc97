// Private: Gaussian taps and the choice of brick kernels for this CPU (brick_filters.h).
#include "brick_filters.h"

#include <algorithm>
#include <cmath>

namespace riemesh::vdb::detail {

namespace generic {
extern const BrickKernels kKernels;
}
#ifdef RIEMESH_HAVE_AVX2_KERNELS
namespace avx2 {
extern const BrickKernels kKernels;
}
#endif

std::vector<float> gaussianTaps(double sigma)
{
    const int radius = std::max(1, int(std::ceil(3.0 * sigma)));
    std::vector<float> w(2 * radius + 1);
    double sum = 0;
    for (int t = -radius; t <= radius; ++t) sum += (w[t + radius] = float(std::exp(-0.5 * t * t / (sigma * sigma))));
    for (auto& x : w) x = float(x / sum);
    return w;
}

const BrickKernels& brickKernels()
{
#ifdef RIEMESH_HAVE_AVX2_KERNELS
    static const bool avx2 = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    if (avx2) return avx2::kKernels;
#endif
    return generic::kKernels;
}

} // namespace riemesh::vdb::detail
