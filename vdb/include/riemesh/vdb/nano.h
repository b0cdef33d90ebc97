// riemesh/vdb/nano.h: OpenVDB -> NanoVDB for the core and the web viewer.
//
// A riemesh .nvdb file holds the image (a float grid, first) and optionally the metric as the Vec3f
// grids "metric_diag" and "metric_off" (see metric_grid.h), uncompressed so that the browser can read
// it without zlib. riemesh::NanoVolume (core/image.h) reads it.
#pragma once

#include "riemesh/image.h"

#include <openvdb/openvdb.h>

#include <nanovdb/util/GridHandle.h>

#include <limits>
#include <string>
#include <vector>

namespace riemesh::vdb {

nanovdb::GridHandle<nanovdb::HostBuffer> toNano(const openvdb::FloatGrid& grid);
nanovdb::GridHandle<nanovdb::HostBuffer> toNano(const openvdb::Vec3fGrid& grid);

using FloatGrids = std::vector<openvdb::FloatGrid::Ptr>;

/// The image, optional metric (both metric grids or neither) and coarse levels (coarseLevels) as
/// NanoVDB handles, image first.
std::vector<nanovdb::GridHandle<nanovdb::HostBuffer>>
toNanoHandles(const openvdb::FloatGrid& image, const openvdb::Vec3fGrid* metricDiag = nullptr,
              const openvdb::Vec3fGrid* metricOff = nullptr, const FloatGrids& levels = {});

/// The same as an in-memory riemesh::NanoVolume (what the core evolves against).
NanoVolume toNanoVolume(const openvdb::FloatGrid& image, const openvdb::Vec3fGrid* metricDiag = nullptr,
                        const openvdb::Vec3fGrid* metricOff = nullptr, const FloatGrids& levels = {});

/// Writes a .nvdb file atomically (temporary file beside `path`, then rename); a finite `iso` is
/// stored with it (grid riemesh::kIsoGrid) for viewers.
void writeNvdb(const std::string& path, const openvdb::FloatGrid& image,
               const openvdb::Vec3fGrid* metricDiag = nullptr, const openvdb::Vec3fGrid* metricOff = nullptr,
               double iso = std::numeric_limits<double>::quiet_NaN(), const FloatGrids& levels = {});

/// Writes the grids of `volume` (and a finite `iso`, as above) to a .nvdb file atomically.
void writeNvdb(const std::string& path, const NanoVolume& volume, double iso = std::numeric_limits<double>::quiet_NaN());

} // namespace riemesh::vdb
