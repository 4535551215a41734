// The published figures the skinning suite's rows stand beside (issue #23): the same dataset, the
// same protocol and bone count, the same quantity. The suite prints them with its measurements and
// puts them in its JSON, so that a reader of either sees the anchor in the same place as the row.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace animspace::bench {

struct SkinningAnchor {
  std::string dataset;   // "horse-gallop", "crane"
  std::string protocol;  // "all_frames", "even_odd"
  std::string method;    // "lbs", "animspace"
  int bones = 0;
  std::string quantity;  // the row's JSON key: "e_rms" or "rmse_over_diag_test"
  double value = 0;      // in that key's units
  std::string source;    // who published it (or "target" for a goal derived from it)
};

// SSDR (Le & Deng 2012) and Hyperspectral Inverse Skinning E_RMS on horse-gallop's 48 frames; Dem
// Bones' held-out RMSE (even frames → odd) on horse-gallop and crane, and the target for
// animation space there, 0.8 × Dem Bones.
const std::vector<SkinningAnchor>& skinning_anchors();

struct AnchorComparison {
  SkinningAnchor anchor;
  bool measured = false;  // a "decomposition" row of that dataset, protocol, method and bones exists
  double value = 0;       // its `quantity`
  bool met = false;       // value ≤ anchor.value
};

// Each anchor against the matching "decomposition" row of `rows` (the suite's JSON rows); rows
// matched get "anchor" and "anchor_source" keys.
std::vector<AnchorComparison> compare_with_anchors(nlohmann::json& rows);

// The comparison as a table on stdout: anchor, ours, met (or "not measured in this run").
void print_anchor_table(const std::vector<AnchorComparison>& comparisons);

}  // namespace animspace::bench
