// The model search: forward-backward stepwise selection over the catalogue
// (and registered user effects) from the user's model, by BIC on the
// reading-space chi-square. An addition must also pass the likelihood-ratio
// test at the verdict's level (kFindingLevel, Bonferroni over the
// candidates tried), so that the search never adds what the verdict would
// call insignificant; a removal is taken whenever it lowers the BIC, so no
// effect stays whose removal lowers the criterion. Each step takes the move
// (add or remove) that lowers the BIC most; when neither does, the best
// one-effect swap that does; a set once visited is not visited again.
#pragma once

#include <functional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "calib/search/candidates.h"

namespace cdm {
namespace diag {

struct SearchStep {
    int step = 0;
    std::string added, removed;
    double bic_change = 0, x_rms_mm = 0;
};

struct SearchResult {
    explicit SearchResult(const DeviceGeometry &g) : model(g) {}
    std::vector<std::string> effects; // the recommended reading-space effects
    Model model;                      // fitted
    FitReport rep;
    double chi2 = 0, bic = 0;
    Eval E;
    std::vector<SearchStep> path;
    // Candidates on top of the recommended model (the last forward step),
    // scored (their tests) but not completed: the diagnosis completes the
    // last search's only (complete_candidates, weighed as the recommended
    // model weighs), since a search followed by another is work thrown away
    // (completing every search's table, a third of the diagnosis's
    // complete_candidates would go to tables never shown; the stages' times:
    //   python3 scripts/progress_times.py build/src/cli/cdm calib diagnose X.csv
    // docs/performance.md, "The whole diagnosis", has the last measurement).
    std::vector<Candidate> cands;
    // Every set fitted on the way: its effects and BIC (for the alternatives).
    std::vector<std::pair<std::vector<std::string>, double>> visited;
    // Every set the search stood on (sorted names), those of seen_before
    // included.
    std::set<std::vector<std::string>> seen;
    // Stopped where its screen found no move, and `restarts` said the
    // search goes on from here under another noise model (cands are then
    // the screen's: not a table to show).
    bool provisional = false;
};

// start: the user's model, fitted (its Position-stage effects are ignored).
// swaps: when no addition or removal lowers the criterion, try every
// one-effect swap (the costliest step: effects in the model × catalogue);
// without, the search stops there. The diagnosis searches without swaps
// while its noise model is still being re-estimated, and with them once it
// has settled (a swap judged under a noise model about to change is work
// thrown away).
// seen_before: sets an earlier search under the same noise model stood on,
// not stood on again. Each move lowers the BIC as the model it leaves
// weighs the data, and those weights differ from model to model, so two
// models could each be preferred from the other: a search that went on
// from another's end without its sets could go back and forth.
// restarts: true for a model's evaluation when the diagnosis will search
// again from that model under a noise model re-estimated from it. A step
// whose screen (search.cpp) finds no move then ends the search without
// fitting every candidate in full: those fits would be judged under a noise
// model about to change, and the next search fits them under the new one
// (as the swaps, above).
bool model_search(const DiagContext &ctx, const Model &start, const FitReport &start_rep,
                  bool swaps, SearchResult &out, std::string &err,
                  const std::set<std::vector<std::string>> *seen_before = nullptr,
                  const std::function<bool(const Eval &)> &restarts = nullptr);

// The models the data cannot tell from the recommended one: every set
// visited within 10 of its BIC (not a superset of it: those add what the data
// do not need) and every one-effect swap of it within 10 (fitted here).
bool search_alternatives(const DiagContext &ctx, const SearchResult &r,
                         std::vector<std::pair<std::vector<std::string>, double>> &alts, std::string &err);

} // namespace diag
} // namespace cdm
