// The catalogue rendered from the registry, for docs/calibration.md and
// docs/effects.md (a model test fails when a page's copy differs, and
// rewrites it with CDM_UPDATE_DOCS=1).
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

std::string stages_markdown() {
    struct Row {
        Stage stage;
        const char *title, *changes;
    };
    static const Row rows[] = {
        {Stage::Jig, "Jig", "the jig's reference position, mapped into the device frame"},
        {Stage::Geometry, "Geometry", "each cable's anchor and holder attachment point"},
        {Stage::Path, "Path", "the cable's length from anchor to holder"},
        {Stage::Transfer, "Transfer", "the pot: counted length → reading"},
        {Stage::User, "User", "the lengths (path stage) or the readings (reading stage), by user callbacks "
                              "(`cdm_effect_register`, plugins, Python, C#)"},
        {Stage::Position, "Position", "the estimated position (not a reading effect; not fitted with the others)"},
    };
    std::ostringstream os;
    os << "| stage | what it changes | built-ins, in order |\n|---|---|---|\n";
    for (const Row &r : rows) {
        std::string names;
        for (const auto &e : all_effects())
            if (e->builtin_id >= 0 && e->stage == r.stage) names += (names.empty() ? "`" : ", `") + e->name + "`";
        os << "| " << r.title << " | " << r.changes << " | " << (names.empty() ? "in the model's order" : names)
           << " |\n";
    }
    return os.str();
}

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
