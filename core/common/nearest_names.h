// "Did you mean …?": the names a typo was probably meant to be, for messages that refuse an
// unknown name (a model the server does not serve, a subcommand the CLI does not have).
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace animspace {

// Up to three of `candidates` nearest to `name` by edit distance (optimal string alignment:
// insertions, deletions, substitutions and swaps of neighbours, one each), nearest first, ties in
// the candidates' order; only names within max(2, |name| / 3) edits — a typo, not another name.
std::vector<std::string> nearest_names(std::string_view name, const std::vector<std::string>& candidates);

}  // namespace animspace
