// What `cdm record` needs to know of its URI and files before it opens
// anything (record_files.cpp): the files a URI reads, whether its source is
// paced by a clock, the recording format an output's name asks for, and
// the checks and fsync that keep an output from replacing an input or
// being half there after a crash.
#pragma once

#include <string>
#include <vector>

namespace cdm::cli {

// The query's options, `key=value` in order ("a&b=1" gives {"a", ""},
// {"b", "1"}). libcdm refuses a URI that repeats one; this reads the first.
std::vector<std::pair<std::string, std::string>> uri_options(const std::string &uri);
// The files a URI reads: replay:PATH, and a sim:'s device=, truth= and jig_plan= options.
std::vector<std::string> uri_inputs(const std::string &uri);
// A source no clock paces: a replay at speed=0, a sim: at realtime=0 (the
// value read as a number). It waits for whoever reads it.
bool unpaced(const std::string &uri);
// Throws UsageError when FILE (or FILE.tmp) exists and is not a regular file,
// or is one of the URI's inputs or of `also` (the command's other input
// files; "" skipped): before anything opens.
void check_output(const std::string &uri, const std::string &file, const std::vector<std::string> &also = {});
// The recording format FILE's extension asks for (cdm_recorder_open_ex's
// names): "mcap", "csv" or "cdmrec".
const char *format_of(const std::string &file);
// fsync of a complete file before its rename: after a crash FILE is the
// old one or the whole new one, never an empty one. "" or what failed.
std::string sync_file(const std::string &path);

} // namespace cdm::cli
