// `animspace train-illumination`: the seeds' second application (Meyer & Anderson 2007 §3.2):
// gather the Cornell box's indirect illumination for a grid of point lights under the ceiling,
// train a PMSC model of the RGB radiance and write a model version that carries its
// illumination engine (server fail-through for a request's lights).
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "core/illumination/illumination_model.h"

namespace animspace::cli {

struct TrainIlluminationArgs {
  int points = 100000;         // target surface sample points (vertices)
  int samples = illumination::IlluminationTrainingOptions{}.gather.samples;  // final-gather rays per point
  // Issue #38: the hits read the direct light from their triangles' vertices (GatherOptions).
  bool direct_from_vertices = illumination::IlluminationTrainingOptions{}.gather.direct_from_vertices;
  // Issue #38: a vertex's value is the mean over its cell (GatherOptions::cell_average).
  bool cell_average = illumination::IlluminationTrainingOptions{}.gather.cell_average;
  // Issue #38: shadow rays from each vertex's cell for its stored direct light
  // (GatherOptions::cell_shadow_rays); < 0: the training's default with --direct-from-vertices, 0
  // without.
  int cell_shadow_rays = -1;
  unsigned long long seed = 0;
  int lights_x = illumination::LightGrid{}.nx;  // training grid (the papers': 12 × 12 = 144)
  int lights_z = illumination::LightGrid{}.nz;
  double drop = illumination::LightGrid{}.drop;
  double inset = illumination::LightGrid{}.inset;
  double tolerance = illumination::IlluminationTrainingOptions{}.tolerance_fraction;
  bool absolute_tolerance = !illumination::IlluminationTrainingOptions{}.relative_tolerance;
  double error_bound = illumination::IlluminationTrainingOptions{}.error_bound_fraction;
  double false_hit_rate = pmsc::TrainingOptions{}.false_hit_rate;
  // Issue #38 item 1: the surface filter's k (0: none) and its normal test; rays per key point.
  int filter_neighbours = illumination::IlluminationTrainingOptions{}.filter.neighbours;
  double filter_min_normal_cosine = illumination::SurfaceFilterOptions{}.min_normal_cosine;
  bool filter_linear = illumination::IlluminationTrainingOptions{}.filter.linear;
  int key_samples = illumination::IlluminationTrainingOptions{}.key_samples;
  int basis = 0;
  double basis_slack = illumination::IlluminationTrainingOptions{}.pmsc.held_out_basis_slack;
  int max_key_points = illumination::IlluminationTrainingOptions{}.pmsc.max_key_points;
  int regions = 8;
  std::string description;
  std::string output;
  std::string model;
  unsigned version = 0;
};

CLI::App* add_train_illumination(CLI::App& app, TrainIlluminationArgs& args);
int run_train_illumination(const TrainIlluminationArgs& args, bool json);

}  // namespace animspace::cli
