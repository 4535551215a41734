// The animspace-bench suites. Each prints its table and returns its results as JSON.
#pragma once

#include <nlohmann/json.hpp>

#include "bench/bench_support.h"

namespace animspace::bench {

nlohmann::json run_io_suite(const SuiteOptions& options);
nlohmann::json run_pmsc_suite(const SuiteOptions& options);
nlohmann::json run_skinning_suite(const SuiteOptions& options);
nlohmann::json run_lod_suite(const SuiteOptions& options);
nlohmann::json run_subdivision_suite(const SuiteOptions& options);
nlohmann::json run_atlas_suite(const SuiteOptions& options);
nlohmann::json run_serve_suite(const SuiteOptions& options);
nlohmann::json run_render_suite(const SuiteOptions& options);
nlohmann::json run_loadtest_suite(const SuiteOptions& options);
nlohmann::json run_illumination_suite(const SuiteOptions& options);
nlohmann::json run_scale_suite(const SuiteOptions& options);

}  // namespace animspace::bench
