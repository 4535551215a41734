#include "bench/skinning_anchors.h"

#include <cstdio>

namespace animspace::bench {

const std::vector<SkinningAnchor>& skinning_anchors() {
  static const std::vector<SkinningAnchor> anchors = {
      {"horse-gallop", "all_frames", "lbs", 10, "e_rms", 5.65, "SSDR"},
      {"horse-gallop", "all_frames", "lbs", 20, "e_rms", 2.80, "SSDR"},
      {"horse-gallop", "all_frames", "lbs", 30, "e_rms", 1.76, "SSDR"},
      {"horse-gallop", "all_frames", "animspace", 10, "e_rms", 4.54, "Hyperspectral Inverse Skinning"},
      {"horse-gallop", "all_frames", "animspace", 20, "e_rms", 1.16, "Hyperspectral Inverse Skinning"},
      {"horse-gallop", "all_frames", "animspace", 30, "e_rms", 0.45, "Hyperspectral Inverse Skinning"},
      {"horse-gallop", "even_odd", "lbs", 16, "rmse_over_diag_test", 0.00339, "Dem Bones"},
      {"horse-gallop", "even_odd", "lbs", 32, "rmse_over_diag_test", 0.00123, "Dem Bones"},
      {"horse-gallop", "even_odd", "animspace", 16, "rmse_over_diag_test", 0.8 * 0.00339, "target: 0.8 × Dem Bones"},
      {"horse-gallop", "even_odd", "animspace", 32, "rmse_over_diag_test", 0.8 * 0.00123, "target: 0.8 × Dem Bones"},
      {"crane", "even_odd", "lbs", 24, "rmse_over_diag_test", 0.00248, "Dem Bones"},
      {"crane", "even_odd", "animspace", 24, "rmse_over_diag_test", 0.8 * 0.00248, "target: 0.8 × Dem Bones"},
  };
  return anchors;
}

std::vector<AnchorComparison> compare_with_anchors(nlohmann::json& rows) {
  std::vector<AnchorComparison> out;
  for (const SkinningAnchor& anchor : skinning_anchors()) {
    AnchorComparison c{anchor};
    for (nlohmann::json& row : rows) {
      if (row.value("fit", "") != "decomposition" || row.value("dataset", "") != anchor.dataset ||
          row.value("protocol", "") != anchor.protocol || row.value("method", "") != anchor.method ||
          row.value("bones", 0) != anchor.bones || !row.contains(anchor.quantity)) {
        continue;
      }
      c.measured = true;
      c.value = row.at(anchor.quantity).get<double>();
      c.met = c.value <= anchor.value;
      row["anchor"] = anchor.value;
      row["anchor_source"] = anchor.source;
      break;
    }
    out.push_back(c);
  }
  return out;
}

void print_anchor_table(const std::vector<AnchorComparison>& comparisons) {
  std::printf("\nanchors (published figures beside this run's decomposition rows; E_RMS as above, RMSE in %% of "
              "the diagonal):\n");
  std::printf("%-13s %-10s %-9s %5s %-9s %10s %10s  %-4s %s\n", "dataset", "protocol", "method", "bones", "quantity",
              "anchor", "ours", "met", "source");
  for (const AnchorComparison& c : comparisons) {
    const bool percent = c.anchor.quantity != "e_rms";
    const double scale = percent ? 100.0 : 1.0;
    char ours[32] = "—";
    if (c.measured) std::snprintf(ours, sizeof ours, "%.4g", scale * c.value);
    std::printf("%-13s %-10s %-9s %5d %-9s %10.4g %10s  %-4s %s\n", c.anchor.dataset.c_str(),
                c.anchor.protocol.c_str(), c.anchor.method.c_str(), c.anchor.bones, percent ? "rmse%d_te" : "E_RMS",
                scale * c.anchor.value, ours, c.measured ? (c.met ? "yes" : "no") : "—",
                c.measured ? c.anchor.source.c_str() : (c.anchor.source + " (not measured in this run)").c_str());
  }
}

}  // namespace animspace::bench
