// Fuzzes the .nvdb reader (core NanoVolume::fromBytes: riemesh's own NanoVDB file parsing and grid
// validation), then touches what the converter and the viewer use: the image's values and
// gradient through NanoImage, and the metric bound.
#include "fuzz_support.h"
#include "riemesh/image.h"

#include <cmath>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    using namespace riemesh;
    fuzz::expectCleanRefusal([&] {
        const NanoVolume volume = NanoVolume::fromBytes(data, size);
        fuzz::require(volume.imageGrid() != nullptr, "accepted volume without image grid");
        fuzz::require(bool(volume.metricDiag()) == bool(volume.metricOff()), "half a metric accepted");
        (void)volume.imageName();
        (void)volume.imageClass();
        const NanoImage image(volume.imageGrid());
        const Box3 box = image.bounds();
        // Sample a few points across the box (and outside it): every lookup walks the tree.
        for (int i = 0; i <= 4; ++i) {
            const Vec3 p = box.min() + (box.max() - box.min()) * (i / 3.0);
            if (!p.allFinite()) break;
            double v;
            Vec3 g;
            image.sample(p, v, g);
        }
    });
    return 0;
}
