#include "io/json.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <map>

#include "io/file.h"

namespace cdm::io {

namespace {
// Deep enough for any calibration (depth 4), shallow enough that "[[[[..."
// cannot exhaust the stack of a reader thread.
constexpr int kMaxDepth = 64;

class Parser {
public:
    Parser(const std::string &t, const std::string &src) : t_(t), src_(src) {}

    bool document(JsonValue &out, std::string &err) {
        skip_ws();
        if (!value(out, 0)) {
            err = err_;
            return false;
        }
        skip_ws();
        if (i_ != t_.size()) {
            err = at() + "unexpected " + token() + " after the end of the JSON document";
            return false;
        }
        return true;
    }

private:
    const std::string &t_;
    const std::string &src_;
    size_t i_ = 0, line_ = 1, col_ = 1;
    std::string err_;

    std::string at() const { return src_ + ":" + std::to_string(line_) + ":" + std::to_string(col_) + ": "; }
    std::string token() const {
        if (i_ >= t_.size()) return "end of file";
        size_t e = i_;
        while (e < t_.size() && e - i_ < 60 && !std::strchr(" \t\r\n,:]}", t_[e])) ++e;
        if (e == i_) ++e;
        return "'" + quote_field(t_.substr(i_, e - i_)) + "'";
    }
    bool fail(const std::string &what) {
        err_ = at() + what;
        return false;
    }
    void adv() {
        if (t_[i_] == '\n') {
            ++line_;
            col_ = 1;
        } else {
            ++col_;
        }
        ++i_;
    }
    void skip_ws() {
        while (i_ < t_.size() && (t_[i_] == ' ' || t_[i_] == '\t' || t_[i_] == '\n' || t_[i_] == '\r')) adv();
    }
    bool literal(const char *word) {
        const size_t n = std::strlen(word);
        if (t_.compare(i_, n, word) != 0) return fail("expected a JSON value, found " + token());
        for (size_t k = 0; k < n; ++k) adv();
        return true;
    }

    bool value(JsonValue &v, int depth) {
        v.line = line_;
        v.col = col_;
        if (i_ >= t_.size()) return fail("expected a JSON value, found the end of the file");
        const char c = t_[i_];
        if (c == '{' || c == '[') {
            if (depth >= kMaxDepth) return fail("JSON nested deeper than " + std::to_string(kMaxDepth) + " levels");
            return c == '{' ? object(v, depth) : array(v, depth);
        }
        if (c == '"') {
            v.type = JsonValue::String;
            return string(v.str);
        }
        if (c == 't' || c == 'f') {
            v.type = JsonValue::Bool;
            v.boolean = c == 't';
            return literal(c == 't' ? "true" : "false");
        }
        if (c == 'n') return literal("null");
        if (c == '-' || (c >= '0' && c <= '9')) return number(v);
        return fail("expected a JSON value, found " + token());
    }

    bool object(JsonValue &v, int depth) {
        v.type = JsonValue::Object;
        adv();
        skip_ws();
        if (i_ < t_.size() && t_[i_] == '}') {
            adv();
            return true;
        }
        // The keys seen, each with its member's index: a duplicate is found
        // in O(log n); a scan of the members would cost n^2 / 2 compares
        // on an object of n keys, and a 64 MiB file holds millions.
        std::map<std::string, size_t> seen;
        for (;;) {
            skip_ws();
            if (i_ >= t_.size() || t_[i_] != '"') return fail("expected a quoted key, found " + token());
            const size_t kl = line_, kc = col_;
            std::string key;
            if (!string(key)) return false;
            const auto [at, fresh] = seen.emplace(key, v.members.size());
            if (!fresh) {
                err_ = src_ + ":" + std::to_string(kl) + ":" + std::to_string(kc) + ": duplicate key \"" +
                       quote_field(key) + "\" (first at line " + std::to_string(v.members[at->second].second.line) +
                       ")";
                return false;
            }
            skip_ws();
            if (i_ >= t_.size() || t_[i_] != ':') return fail("expected ':' after the key, found " + token());
            adv();
            skip_ws();
            v.members.emplace_back(std::move(key), JsonValue{});
            if (!value(v.members.back().second, depth + 1)) return false;
            skip_ws();
            if (i_ < t_.size() && t_[i_] == ',') {
                adv();
                continue;
            }
            if (i_ < t_.size() && t_[i_] == '}') {
                adv();
                return true;
            }
            return fail("expected ',' or '}' in the object, found " + token());
        }
    }

    bool array(JsonValue &v, int depth) {
        v.type = JsonValue::Array;
        adv();
        skip_ws();
        if (i_ < t_.size() && t_[i_] == ']') {
            adv();
            return true;
        }
        for (;;) {
            skip_ws();
            v.items.emplace_back();
            if (!value(v.items.back(), depth + 1)) return false;
            skip_ws();
            if (i_ < t_.size() && t_[i_] == ',') {
                adv();
                continue;
            }
            if (i_ < t_.size() && t_[i_] == ']') {
                adv();
                return true;
            }
            return fail("expected ',' or ']' in the array, found " + token());
        }
    }

    bool number(JsonValue &v) {
        const size_t b = i_;
        size_t e = i_;
        auto digits = [&]() {
            const size_t s = e;
            while (e < t_.size() && t_[e] >= '0' && t_[e] <= '9') ++e;
            return e > s;
        };
        if (t_[e] == '-') ++e;
        if (e < t_.size() && t_[e] == '0') {
            ++e;
        } else if (!digits()) {
            return fail("malformed number " + token());
        }
        if (e < t_.size() && t_[e] == '.') {
            ++e;
            if (!digits()) return fail("malformed number " + token() + " (digits must follow '.')");
        }
        if (e < t_.size() && (t_[e] == 'e' || t_[e] == 'E')) {
            ++e;
            if (e < t_.size() && (t_[e] == '+' || t_[e] == '-')) ++e;
            if (!digits()) return fail("malformed number " + token() + " (digits must follow the exponent)");
        }
        double d = 0;
        auto r = std::from_chars(t_.data() + b, t_.data() + e, d);
        if (r.ec == std::errc::result_out_of_range)
            return fail("number " + token() + " is out of the range of a double (overflow or underflow)");
        if (r.ec != std::errc() || r.ptr != t_.data() + e) return fail("malformed number " + token());
        v.type = JsonValue::Number;
        v.number = d;
        while (i_ < e) adv();
        return true;
    }

    static void utf8(unsigned cp, std::string &o) {
        if (cp < 0x80) {
            o += char(cp);
        } else if (cp < 0x800) {
            o += char(0xC0 | (cp >> 6));
            o += char(0x80 | (cp & 0x3F));
        } else if (cp < 0x10000) {
            o += char(0xE0 | (cp >> 12));
            o += char(0x80 | ((cp >> 6) & 0x3F));
            o += char(0x80 | (cp & 0x3F));
        } else {
            o += char(0xF0 | (cp >> 18));
            o += char(0x80 | ((cp >> 12) & 0x3F));
            o += char(0x80 | ((cp >> 6) & 0x3F));
            o += char(0x80 | (cp & 0x3F));
        }
    }

    bool hex4(unsigned &cp) {
        cp = 0;
        for (int k = 0; k < 4; ++k) {
            if (i_ >= t_.size()) return fail("unfinished \\u escape");
            const char h = t_[i_];
            unsigned d = (h >= '0' && h <= '9') ? unsigned(h - '0')
                         : (h >= 'a' && h <= 'f') ? unsigned(h - 'a' + 10)
                         : (h >= 'A' && h <= 'F') ? unsigned(h - 'A' + 10)
                                                  : 16u;
            if (d == 16) return fail("bad hex digit in a \\u escape");
            cp = cp * 16 + d;
            adv();
        }
        return true;
    }

    bool string(std::string &o) {
        adv(); // opening quote
        for (;;) {
            if (i_ >= t_.size()) return fail("unterminated string (end of file)");
            const unsigned char c = static_cast<unsigned char>(t_[i_]);
            if (c == '"') {
                adv();
                return true;
            }
            if (c < 0x20) return fail("control character (byte " + std::to_string(c) + ") inside a string");
            if (c != '\\') {
                o += char(c);
                adv();
                continue;
            }
            adv();
            if (i_ >= t_.size()) return fail("unterminated escape");
            const char e = t_[i_];
            adv();
            switch (e) {
            case '"': o += '"'; break;
            case '\\': o += '\\'; break;
            case '/': o += '/'; break;
            case 'b': o += '\b'; break;
            case 'f': o += '\f'; break;
            case 'n': o += '\n'; break;
            case 'r': o += '\r'; break;
            case 't': o += '\t'; break;
            case 'u': {
                unsigned cp;
                if (!hex4(cp)) return false;
                if (cp >= 0xD800 && cp < 0xDC00) {
                    unsigned lo;
                    if (t_.compare(i_, 2, "\\u") != 0) return fail("lone high surrogate in a \\u escape");
                    adv();
                    adv();
                    if (!hex4(lo)) return false;
                    if (lo < 0xDC00 || lo > 0xDFFF) return fail("bad low surrogate in a \\u escape");
                    cp = 0x10000 + ((cp - 0xD800) << 10) + (lo - 0xDC00);
                } else if (cp >= 0xDC00 && cp <= 0xDFFF) {
                    return fail("lone low surrogate in a \\u escape");
                }
                if (cp == 0) return fail("\\u0000 (NUL) is not allowed in a string");
                utf8(cp, o);
                break;
            }
            default: return fail(std::string("unknown escape '\\") + e + "'");
            }
        }
    }
};
} // namespace

const JsonValue *JsonValue::find(const std::string &key) const {
    if (type != Object) return nullptr;
    for (const auto &m : members)
        if (m.first == key) return &m.second;
    return nullptr;
}

const char *JsonValue::type_name() const {
    switch (type) {
    case Null: return "null";
    case Bool: return "a boolean";
    case Number: return "a number";
    case String: return "a string";
    case Array: return "an array";
    case Object: return "an object";
    }
    return "?";
}

std::string where(const std::string &source, const JsonValue &v) {
    return source + ":" + std::to_string(v.line) + ":" + std::to_string(v.col) + ": ";
}

std::string quote_field(const std::string &s) {
    constexpr size_t kShown = 40;
    if (s.size() <= kShown) return s;
    return s.substr(0, kShown) + "... (" + std::to_string(s.size() - kShown) + " more characters)";
}

namespace {
// Edit distance, for "did you mean": only between short keys (a hostile
// 10^6-character key costs nothing).
size_t edit_distance(const std::string &a, const std::string &b) {
    std::vector<size_t> row(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        size_t diag = row[0];
        row[0] = i;
        for (size_t j = 1; j <= b.size(); ++j) {
            const size_t up = row[j];
            row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0u : 1u)});
            diag = up;
        }
    }
    return row[b.size()];
}
} // namespace

bool only_keys(const JsonValue &obj, std::initializer_list<const char *> allowed, const std::string &source,
               const std::string &what, std::string &err) {
    if (obj.type != JsonValue::Object) return true; // the caller says what type it needs
    for (const auto &m : obj.members) {
        bool known = false;
        for (const char *k : allowed) known = known || m.first == k;
        if (known) continue;
        std::string list, best;
        size_t best_d = 3; // at most two edits away
        for (const char *k : allowed) {
            list += (list.empty() ? "" : ", ") + std::string(k);
            if (m.first.size() > 64) continue;
            const size_t d = edit_distance(m.first, k);
            if (d < best_d) {
                best_d = d;
                best = k;
            }
        }
        err = where(source, m.second) + "unknown key \"" + quote_field(m.first) + "\" in " + what + " (allowed: " +
              list + ")" + (best.empty() ? "" : "; did you mean \"" + best + "\"?");
        return false;
    }
    return true;
}

bool parse_json(const std::string &text, const std::string &source, JsonValue &out, std::string &err) {
    Parser p(text, source);
    JsonValue v;
    if (!p.document(v, err)) return false;
    out = std::move(v);
    return true;
}

bool load_json(const std::string &path, JsonValue &out, std::string &err, const char *what) {
    std::string text;
    return read_file(path, kJsonMaxBytes, text, err, what) && parse_json(text, path, out, err);
}

} // namespace cdm::io
