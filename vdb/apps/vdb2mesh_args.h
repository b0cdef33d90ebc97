// vdb/apps/vdb2mesh_args.h: vdb2mesh's command line, parsed and checked without running anything, so
// that tests and the fuzzer (fuzz/vdb2mesh_args_fuzz.cpp) reach it directly. Every problem is a
// BadInput (exit 1) naming the flag; nothing here reads the input image.
#pragma once

#include "riemesh/mesh.h"
#include "riemesh/vdb/pipeline.h"

#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace riemesh::apps {

// Defaults (documented in --help): the pipeline's (riemesh/vdb/pipeline.h).
using vdb::kDelta;
using vdb::kMaxIterations;
using vdb::kMaxVertices;
using vdb::kMuMax;
using vdb::kRho;
using vdb::kSigma;
using vdb::kSmooth;
using vdb::kTangentialGain;
using vdb::kZeta;

struct Vdb2MeshArgs {
    bool help = false;                 ///< -h/--help: print usage, nothing else
    std::string input, output;
    std::string grid;
    std::optional<double> iso;
    bool riemannian = true;
    double delta = kDelta, zeta = kZeta, muMax = kMuMax, sigma = kSigma, rho = kRho, smooth = -1; ///< smooth: -1 = the default (PipelineOptions::smooth unset)
    int maxIterations = kMaxIterations;
    std::uint64_t maxVertices = kMaxVertices;
    std::uint64_t maxMemory = 0;       ///< bytes; 0 = the default budget (half the physical memory)
    std::string init = "box";
    std::string exportNvdb, writeMetric, stats, reference;
    int threads = 0;
    bool quiet = false;
    bool openBorders = false;          ///< --open-borders: do not close objects cut by the image box
    bool intersectionFree = false;     ///< --intersection-free: the guarantee (EvolutionOptions)
    bool sharpen = true;               ///< creases and corners (PipelineOptions::sharpen); --no-sharpen
    bool faceSamples = false;          ///< --face-samples (PipelineOptions::faceSamples)
    int downsample = 1;                ///< --downsample F: block-average F^3 voxels first
    int levels = -1;                   ///< --levels L (-1: auto)
    double tangentialGain = kTangentialGain; ///< --edge-gain: boost of the metric at edges and corners
};

/// argv[1..argc-1] as flags and the two positionals; the values' ranges are checked here.
Vdb2MeshArgs parseVdb2MeshArgs(int argc, const char* const* argv);

/// The --help text.
void printVdb2MeshUsage(std::FILE* out);

/// "sphere:" specs X,Y,Z,R[;X,Y,Z,R...] (world units), each radius > 0.
std::vector<std::pair<Vec3, double>> parseSpheres(const std::string& spec);

/// A byte count with an optional K/M/G/T suffix (powers of 1024), e.g. "512M", "1.5G", "1000000".
std::uint64_t parseByteCount(const std::string& flag, const std::string& text);

/// The output file's extension is one of `extensions`, its folder exists and it is not a folder.
void checkOutputPath(const std::string& path, const std::vector<std::string>& extensions, const char* what);

} // namespace riemesh::apps
