// The catalogue rendered from the registry, for docs/calibration.md (a
// model test fails when the page's copy differs).
#include <sstream>

#include "model/effect.h"

namespace cdm {

namespace {
const char *stage_name(Stage s) {
    switch (s) {
    case Stage::Jig: return "jig";
    case Stage::Geometry: return "geometry";
    case Stage::Path: return "path";
    case Stage::Transfer: return "transfer";
    case Stage::User: return "user";
    case Stage::Position: return "position";
    }
    return "?";
}
// A '|' inside a cell would end it.
std::string cell(const std::string &t) {
    std::string o;
    for (char c : t) {
        if (c == '|') o += '\\';
        o += c;
    }
    return o;
}
} // namespace

std::string catalogue_markdown() {
    std::ostringstream os;
    os << "| # | effect | stage | physics | parameters |\n|---|---|---|---|---|\n";
    int n = 0;
    for (const auto &e : all_effects()) {
        if (e->builtin_id < 0) continue;
        os << "| " << ++n << " | `" << e->name << "` | " << stage_name(e->stage) << " | " << cell(e->doc) << " | ";
        for (size_t k = 0; k < e->params.size(); ++k)
            os << (k ? ", " : "") << e->params[k].name << (e->params[k].unit.empty() ? "" : " (" + e->params[k].unit + ")");
        os << " |\n";
    }
    return os.str();
}

} // namespace cdm
