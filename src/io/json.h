// The one JSON loader: every value keeps the line and column where it
// starts, so the codecs can say "dev.json:3:10: a_mm = -5 ...". Refuses what
// a permissive parser lets through: numbers that overflow a double, trailing
// bytes after the document, duplicate keys, nesting past a fixed depth.
#pragma once

#include <cstddef>
#include <initializer_list>
#include <string>
#include <utility>
#include <vector>

namespace cdm::io {

struct JsonValue {
    enum Type { Null, Bool, Number, String, Array, Object };
    Type type = Null;
    bool boolean = false;
    double number = 0;
    std::string str;
    std::vector<JsonValue> items;                           // Array
    std::vector<std::pair<std::string, JsonValue>> members; // Object, in file order
    size_t line = 0, col = 0;                               // 1-based start of the value

    const JsonValue *find(const std::string &key) const; // Object member or nullptr
    const char *type_name() const;
};

// "source:line:col: " for messages about `v`.
std::string where(const std::string &source, const JsonValue &v);

// A field of user input quoted in a message: at most ~40 characters, the
// rest replaced by "... (N more characters)", so a 10^6-digit field is not
// echoed whole.
std::string quote_field(const std::string &s);

// The schema check of an object: every member's key must be one of
// `allowed` (a misspelt key would otherwise be ignored and its default
// used). Errors read "source:line:col: unknown key "effect" in <what>
// (allowed: ...); did you mean "effects"?", at the member's value.
bool only_keys(const JsonValue &obj, std::initializer_list<const char *> allowed, const std::string &source,
               const std::string &what, std::string &err);

// Parses a complete JSON document. Errors read
// "source:line:col: <what is wrong>" in words.
bool parse_json(const std::string &text, const std::string &source, JsonValue &out, std::string &err);

// read_file (regular file, capped at kJsonMaxBytes) then parse_json.
bool load_json(const std::string &path, JsonValue &out, std::string &err, const char *what);

} // namespace cdm::io
