// OpenFOAM dictionaries expanded as OpenFOAM reads them (see FoamDict.h): a lexer close to
// OpenFOAM's ISstream, a dictionary tree built entry by entry (so `$var` sees what OpenFOAM's sees
// at that point), OpenFOAM's scoped search (dictionarySearch.C) and its boundaryField matching
// (GeometricBoundaryField.C), then the tree written back as plain text for VTK's reader.
#include "io/mesh/FoamDict.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <regex>
#include <unordered_map>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

namespace {

constexpr int kMaxIncludeDepth = 16;
constexpr int kMaxDictDepth = 64;
constexpr std::size_t kMaxFileBytes = std::size_t(1) << 30;
constexpr std::size_t kMinBudget = std::size_t(64) << 20;

[[noreturn]] void fail(const std::string& msg) { throw lic::InputError(msg); }

const std::vector<std::string>& constraintTypes()
{
    static const std::vector<std::string> types = {"cyclic",    "cyclicAMI",     "cyclicACMI",
                                                    "cyclicSlip", "empty",         "nonuniformTransformCyclic",
                                                    "processor", "processorCyclic", "symmetryPlane",
                                                    "symmetry",  "wedge",         "overset"};
    return types;
}

bool constraintWithValue(const std::string& type)
{
    return type == "cyclicACMI" || type == "processor" || type == "processorCyclic";
}

bool isInclude(const std::string& directive)
{
    return directive == "#include" || directive == "#includeEtc" || directive == "#includeIfPresent" ||
           directive == "#sinclude" || directive == "#sincludeEtc";
}

bool isConstraintType(const std::string& type)
{
    const auto& t = constraintTypes();
    return std::find(t.begin(), t.end(), type) != t.end();
}

// ---- lexer ------------------------------------------------------------------------------------

struct Source
{
    fs::path file;
    std::string text;
};

enum class Tok { End, Word, String, Punct, Variable, Directive, Verbatim, Raw };

struct Token
{
    Tok kind = Tok::End;
    std::string text; // as written (strings with their quotes, variables with their '$')
    char sep = ' ';   // what stood before it: 0 nothing, ' ' blanks or a comment, '\n' a line break
    const Source* src = nullptr;
    int line = 0;
    bool is(char c) const { return kind == Tok::Punct && text.size() == 1 && text[0] == c; }
};

std::string where(const Source* src, int line)
{
    std::string f = src && !src->file.empty() ? src->file.string() : std::string("<dictionary>");
    return f + ":" + std::to_string(line);
}

std::string where(const Token& t) { return where(t.src, t.line); }

bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

/// OpenFOAM's word::valid.
bool wordChar(char c)
{
    return !isSpace(c) && c != '"' && c != '\'' && c != '/' && c != ';' && c != '{' && c != '}';
}

class Lexer
{
public:
    explicit Lexer(const Source& src) : src_(src), s_(src.text) {}

    const Source& source() const { return src_; }

    Token next()
    {
        if (peeked_) {
            Token t = std::move(*peeked_);
            peeked_.reset();
            return t;
        }
        return lex();
    }

    const Token& peek()
    {
        if (!peeked_) peeked_ = lex();
        return *peeked_;
    }

    /// Drop the rest of the current line (parentheses balanced across lines): #includeFunc's arguments.
    void skipLine()
    {
        peeked_.reset(); // a token looked at is part of the line
        int depth = 0;
        while (p_ < s_.size()) {
            const char c = s_[p_];
            if (c == '\n' && depth <= 0) return;
            if (c == '\n') ++line_;
            if (c == '(') ++depth;
            if (c == ')') --depth;
            ++p_;
        }
    }

private:
    char at(std::size_t i) const { return i < s_.size() ? s_[i] : '\0'; }

    [[noreturn]] void error(int line, const std::string& what) const { fail(where(&src_, line) + ": " + what); }

    /// Blanks and comments; the separator they make.
    char skipBlanks()
    {
        char sep = 0;
        while (p_ < s_.size()) {
            const char c = s_[p_];
            if (isSpace(c)) {
                if (c == '\n') {
                    ++line_;
                    sep = '\n';
                } else if (!sep) {
                    sep = ' ';
                }
                ++p_;
            } else if (c == '/' && at(p_ + 1) == '/') {
                while (p_ < s_.size() && s_[p_] != '\n') ++p_;
                if (!sep) sep = ' ';
            } else if (c == '/' && at(p_ + 1) == '*') {
                const int start = line_;
                const std::size_t end = s_.find("*/", p_ + 2);
                if (end == std::string::npos) error(start, "unterminated /* comment");
                line_ += int(std::count(s_.begin() + std::ptrdiff_t(p_), s_.begin() + std::ptrdiff_t(end), '\n'));
                p_ = end + 2;
                if (!sep) sep = ' ';
            } else {
                break;
            }
        }
        return sep;
    }

    Token make(Tok kind, std::size_t begin, char sep, int line)
    {
        Token t;
        t.kind = kind;
        t.text.assign(s_, begin, p_ - begin);
        t.sep = sep;
        t.src = &src_;
        t.line = line;
        line_ += int(std::count(t.text.begin(), t.text.end(), '\n'));
        return t;
    }

    /// A list that holds only numbers and words, e.g. a nonuniform field: one token, kept as written.
    bool rawList()
    {
        if (p_ < noRawUntil_) return false;
        int depth = 0;
        for (std::size_t i = p_; i < s_.size(); ++i) {
            const char c = s_[i];
            if (c == '(') {
                ++depth;
            } else if (c == ')') {
                if (--depth == 0) {
                    rawEnd_ = i + 1;
                    return true;
                }
            } else if (c == '"' || c == '\'' || c == '#' || c == '$' || c == '/' || c == '{' || c == '}' ||
                       c == ';') {
                noRawUntil_ = i;
                return false;
            }
        }
        noRawUntil_ = s_.size();
        return false;
    }

    Token lexString(char sep, int line)
    {
        const std::size_t begin = p_++;
        while (p_ < s_.size() && s_[p_] != '"') p_ += s_[p_] == '\\' ? 2 : 1;
        if (p_ >= s_.size()) error(line, "unterminated string");
        ++p_;
        return make(Tok::String, begin, sep, line);
    }

    /// Word characters, with OpenFOAM's parentheses rule (`div(phi,U)` is one word).
    void wordChars(bool allowSlash)
    {
        int depth = 0;
        while (p_ < s_.size()) {
            const char c = s_[p_];
            if (!(wordChar(c) || (allowSlash && c == '/'))) break;
            if (c == '(') ++depth;
            if (c == ')' && depth-- == 0) break;
            ++p_;
        }
    }

    Token lexHash(std::size_t begin, char sep, int line)
    {
        if (at(p_ + 1) == '{') { // #{ verbatim #}
            const std::size_t end = s_.find("#}", p_ + 2);
            if (end == std::string::npos) error(line, "unterminated #{ … #} block");
            p_ = end + 2;
            return make(Tok::Verbatim, begin, sep, line);
        }
        ++p_;
        while (p_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[p_])) || s_[p_] == '_')) ++p_;
        return make(Tok::Directive, begin, sep, line);
    }

    Token lexDollar(std::size_t begin, char sep, int line)
    {
        ++p_;
        if (at(p_) == '{') {
            int depth = 0;
            while (p_ < s_.size()) {
                const char c = s_[p_++];
                if (c == '{') ++depth;
                if (c == '}' && --depth == 0) break;
            }
            if (depth != 0) error(line, "unterminated ${…}");
        } else {
            wordChars(true);
        }
        return make(Tok::Variable, begin, sep, line);
    }

    Token lex()
    {
        const char sep = skipBlanks();
        const int line = line_;
        const std::size_t begin = p_;
        if (p_ >= s_.size()) {
            Token t;
            t.sep = sep;
            t.src = &src_;
            t.line = line;
            return t;
        }
        const char c = s_[p_];
        if (c == '"') return lexString(sep, line);
        if (c == '#') return lexHash(begin, sep, line);
        if (c == '$') return lexDollar(begin, sep, line);
        if (c == '(' && rawList()) {
            p_ = rawEnd_;
            return make(Tok::Raw, begin, sep, line);
        }
        if (c == ';' || c == '{' || c == '}' || c == '(' || c == ')' || c == '[' || c == ']' || c == ',' ||
            c == '/' || c == '\'') {
            ++p_;
            return make(Tok::Punct, begin, sep, line);
        }
        if (std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '.' || c == '+') {
            while (p_ < s_.size() && wordChar(s_[p_]) && s_[p_] != '(' && s_[p_] != ')' && s_[p_] != '[' &&
                   s_[p_] != ']' && s_[p_] != ',')
                ++p_;
        } else {
            wordChars(false);
        }
        if (p_ == begin) ++p_; // cannot happen for valid input; never loop
        return make(Tok::Word, begin, sep, line);
    }

    const Source& src_;
    const std::string& s_;
    std::size_t p_ = 0;
    int line_ = 1;
    std::size_t noRawUntil_ = 0, rawEnd_ = 0;
    std::optional<Token> peeked_;
};

/// The words of a list token sequence (`2(wall foo)`, `List<word> 1(wall)`, a raw list): names only.
std::vector<std::string> listWords(const std::vector<Token>& tokens)
{
    std::vector<std::string> words;
    bool inList = false;
    for (const Token& t : tokens) {
        if (t.kind == Tok::Raw) {
            Source s{t.src ? t.src->file : fs::path(), t.text.substr(1, t.text.size() - 2)};
            Lexer lx(s);
            for (Token u = lx.next(); u.kind != Tok::End; u = lx.next())
                if (u.kind == Tok::Word) words.push_back(u.text);
            continue;
        }
        if (t.is('(')) inList = true;
        if (t.is(')')) inList = false;
        if (inList && (t.kind == Tok::Word || t.kind == Tok::String))
            words.push_back(t.kind == Tok::String ? t.text.substr(1, t.text.size() - 2) : t.text);
    }
    return words;
}

// ---- dictionary tree --------------------------------------------------------------------------

struct Dict;

struct Entry
{
    std::string key;      // a string key without its quotes
    bool pattern = false; // a quoted key: a regular expression
    std::vector<Token> value;
    std::unique_ptr<Dict> dict; // set: a dictionary entry
    const Source* src = nullptr;
    int line = 0;
    mutable std::optional<std::regex> re;
    mutable bool badRe = false;

    bool matches(const std::string& name) const
    {
        if (!pattern) return key == name;
        if (name.size() > 1024) return false;
        if (!re && !badRe) {
            // libstdc++ compiles bounded repeats by copying: cap them so that a key cannot blow up
            bool tooBig = key.size() > 256 || std::count(key.begin(), key.end(), '{') > 2;
            for (std::size_t i = 0; !tooBig && i < key.size(); ++i)
                if (key[i] == '{' && i + 1 < key.size() && std::isdigit(static_cast<unsigned char>(key[i + 1])))
                    tooBig = std::atoi(key.c_str() + i + 1) > 64;
            try {
                if (tooBig) throw std::regex_error(std::regex_constants::error_complexity);
                re.emplace(key, std::regex::extended);
            } catch (const std::regex_error&) {
                badRe = true;
            }
        }
        if (badRe) return key == name;
        try {
            return std::regex_match(name, *re);
        } catch (const std::regex_error&) {
            return false;
        }
    }
};

struct Dict
{
    Dict* parent = nullptr;
    std::vector<std::unique_ptr<Entry>> entries;
    std::unordered_map<std::string, Entry*> literal;

    const Entry* findLocal(const std::string& key, bool patterns) const
    {
        if (auto it = literal.find(key); it != literal.end()) return it->second;
        if (patterns)
            for (auto it = entries.rbegin(); it != entries.rend(); ++it)
                if ((*it)->pattern && (*it)->matches(key)) return it->get();
        return nullptr;
    }

    Entry* findLiteral(const std::string& key)
    {
        auto it = literal.find(key);
        return it == literal.end() ? nullptr : it->second;
    }

    void remove(const Entry* e)
    {
        literal.erase(e->key);
        entries.erase(std::remove_if(entries.begin(), entries.end(), [&](const auto& p) { return p.get() == e; }),
                      entries.end());
    }

    void reparent()
    {
        for (auto& e : entries)
            if (e->dict) e->dict->parent = this;
    }
};

std::unique_ptr<Dict> cloneDict(const Dict& d, Dict* parent, int depth);

std::unique_ptr<Entry> cloneEntry(const Entry& e, Dict* parent, int depth)
{
    auto c = std::make_unique<Entry>();
    c->key = e.key;
    c->pattern = e.pattern;
    c->value = e.value;
    c->src = e.src;
    c->line = e.line;
    if (e.dict) c->dict = cloneDict(*e.dict, parent, depth + 1);
    return c;
}

std::unique_ptr<Dict> cloneDict(const Dict& d, Dict* parent, int depth)
{
    if (depth > kMaxDictDepth) fail("dictionaries nested more than " + std::to_string(kMaxDictDepth) + " deep");
    auto c = std::make_unique<Dict>();
    c->parent = parent;
    for (const auto& e : d.entries) {
        auto ce = cloneEntry(*e, c.get(), depth);
        c->literal[ce->key] = ce.get();
        c->entries.push_back(std::move(ce));
    }
    return c;
}

enum class Mode { Merge, Overwrite, Default };

/// Add `e` to `d` as OpenFOAM's dictionary::add(entry, mergeEntry) does: a dictionary merges into
/// a dictionary of the same key, anything else replaces the old entry where it stood.
void addEntry(Dict& d, std::unique_ptr<Entry> e, Mode mode, int depth)
{
    // OpenFOAM keys its hash table by the text of every key, "regex" or not
    Entry* old = d.findLiteral(e->key);
    if (!old) {
        if (e->dict) e->dict->parent = &d;
        d.literal[e->key] = e.get();
        d.entries.push_back(std::move(e));
        return;
    }
    if (mode == Mode::Default) return;
    if (mode == Mode::Merge && old->dict && e->dict) {
        if (depth > kMaxDictDepth) fail("dictionaries nested more than " + std::to_string(kMaxDictDepth) + " deep");
        for (auto& sub : e->dict->entries) {
            auto moved = std::move(sub);
            addEntry(*old->dict, std::move(moved), Mode::Merge, depth + 1);
        }
        return;
    }
    for (auto& slot : d.entries)
        if (slot.get() == old) {
            if (e->dict) e->dict->parent = &d;
            d.literal[e->key] = e.get();
            slot = std::move(e);
            return;
        }
}

const Dict* topOf(const Dict* d)
{
    while (d->parent) d = d->parent;
    return d;
}

/// A variable's lookup: by the key's text, as OpenFOAM v1912 does it (`$p` does not match "(p|q)").
const Entry* search(const Dict* d, const std::string& key, bool recursive)
{
    for (; d; d = recursive ? d->parent : nullptr)
        if (const Entry* e = d->findLocal(key, false)) return e;
    return nullptr;
}

/// dictionary::csearchDotScoped: "a.b" looks `a` up here (not outward), then `b` in it; a leading
/// '.' per level up; keys with dots ("a.b") are found too.
const Entry* dotScoped(const Dict* d, const std::string& key, bool recursive, const std::string& what)
{
    std::size_t pos = key.find('.');
    if (pos == std::string::npos) return search(d, key, recursive);
    if (pos == 0) {
        ++pos;
        for (std::size_t i = 1; i < key.size() && key[i] == '.'; ++i, ++pos) {
            if (!d->parent) fail("no parent dictionary for " + what);
            d = d->parent;
        }
        return dotScoped(d, key.substr(pos), false, what);
    }
    const Entry* found = dotScoped(d, key.substr(0, pos), false, what);
    if (!found) {
        while (!(found && found->dict)) {
            pos = key.find('.', pos + 1);
            found = search(d, key.substr(0, pos), false);
            if (pos == std::string::npos) return found;
        }
    }
    if (found && found->dict) return dotScoped(found->dict.get(), key.substr(pos), false, what);
    return found;
}

/// dictionary::csearchSlashScoped: "../x", "a/b", "/a/b".
const Entry* slashScoped(const Dict* d, const std::string& key, const std::string& what)
{
    if (key[0] == '/') d = topOf(d);
    std::vector<std::string> parts;
    for (std::size_t b = 0; b <= key.size();) {
        std::size_t e = key.find('/', b);
        if (e == std::string::npos) e = key.size();
        if (e > b) parts.push_back(key.substr(b, e - b));
        b = e + 1;
    }
    for (std::size_t i = 0; i < parts.size(); ++i) {
        if (parts[i] == ".") continue;
        if (parts[i] == "..") {
            if (!d->parent) fail("no parent dictionary for " + what);
            d = d->parent;
            continue;
        }
        const Entry* found = search(d, parts[i], true);
        if (!found) return nullptr;
        if (i + 1 == parts.size()) return found;
        if (!found->dict) return nullptr;
        d = found->dict.get();
    }
    return nullptr;
}

/// dictionary::csearchScoped, as `$name` uses it (outward search).
const Entry* scopedSearch(const Dict* d, const std::string& name)
{
    if (name.empty()) return nullptr;
    if (name.size() > 1024) fail("$" + name.substr(0, 40) + "…: a variable name longer than 1024 characters");
    if (name.find('/') != std::string::npos) return slashScoped(d, name, "$" + name);
    if (name[0] == ':' || name[0] == '^') return dotScoped(topOf(d), name.substr(1), true, "$" + name);
    return dotScoped(d, name, true, "$" + name);
}

/// scopedSearch with the error placed at `at`.
const Entry* lookup(const Dict& scope, const std::string& name, const Token& at)
{
    try {
        return scopedSearch(&scope, name);
    } catch (const lic::InputError& e) {
        fail(where(at) + ": " + e.what());
    }
}

// ---- expansion --------------------------------------------------------------------------------

std::string unquote(const std::string& s)
{
    return s.size() >= 2 && s.front() == '"' && s.back() == '"' ? s.substr(1, s.size() - 2) : s;
}

std::string q(const std::string& s) { return "\"" + s + "\""; }

std::string joinPaths(const std::vector<fs::path>& dirs)
{
    std::string out;
    for (const auto& d : dirs) out += (out.empty() ? "" : ", ") + d.string();
    return out;
}

std::optional<std::string> readWholeFile(const fs::path& path)
{
    std::error_code ec;
    const std::string s = path.lexically_normal().string();
    for (const char* bad : {"/proc/", "/sys/", "/dev/"}) // never block on a device or a kernel file
        if (s.rfind(bad, 0) == 0) return std::nullopt;
    if (!fs::is_regular_file(path, ec)) return std::nullopt;
    const auto size = fs::file_size(path, ec);
    if (ec || size > kMaxFileBytes) return std::nullopt;
    std::ifstream in(path, std::ios::binary);
    if (!in) return std::nullopt;
    std::string text(size, '\0');
    in.read(text.data(), std::streamsize(size));
    text.resize(std::size_t(in.gcount()));
    return text;
}

class Expander
{
public:
    Expander(const FoamDictContext& ctx, std::size_t inputBytes)
        : ctx_(ctx), budget_(std::max(kMinBudget, inputBytes * 32))
    {
        caseDir_ = ctx.caseDir;
        if (caseDir_.empty() && !ctx.file.empty()) {
            caseDir_ = ctx.file.parent_path().parent_path();
            const std::string leaf = caseDir_.filename().string();
            if (leaf.rfind("processor", 0) == 0 && leaf.size() > 9 &&
                std::all_of(leaf.begin() + 9, leaf.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); }))
                caseDir_ = caseDir_.parent_path();
        }
    }

    const Source& addSource(fs::path file, std::string text)
    {
        bytes_ += text.size();
        return sources_.emplace_back(Source{std::move(file), std::move(text)});
    }

    /// Entries up to the end of `lx` (a file) or the '}' that closes a sub-dictionary.
    void parseEntries(Dict& d, Lexer& lx, int dictDepth, int fileDepth, bool subDict, bool includedFile);

    /// A primitive entry's value: tokens up to ';' with variables and #include expanded (an
    /// included file's tokens up to its first ';', as OpenFOAM's primitiveEntry reads them).
    void readValue(const Dict& scope, Lexer& lx, std::vector<Token>& out, int fileDepth);

    void rewriteBoundary(Dict& root);

private:
    /// Count what an expansion holds (a token: its text and its own size) against the budget.
    void charge(std::size_t n)
    {
        bytes_ += n + sizeof(Token);
        if (bytes_ > budget_)
            fail("the dictionary expands to more than " + std::to_string(budget_ >> 20) + " MiB: a $variable loop?");
    }

    void expandVariable(const Dict& scope, const Token& var, std::vector<Token>& out);
    void appendDictTokens(const Dict& d, const Token& at, std::vector<Token>& out, int depth);
    std::string expandString(const Dict& scope, const std::string& s, const Token& at);
    fs::path resolveInclude(const Dict& scope, const Token& directive, const Token& arg);
    std::optional<fs::path> findEtc(const std::string& name) const;
    /// The file of an #include-like directive (its argument read from lx); nullopt: optional and absent.
    std::optional<const Source*> includeSource(const Dict& scope, Lexer& lx, const Token& directive, int fileDepth);
    bool directiveAtKeyword(Dict& d, Lexer& lx, const Token& t, int dictDepth, int fileDepth, Mode& mode);
    void mergeVariable(Dict& d, const Token& t, int dictDepth);
    void removeEntries(Dict& d, Lexer& lx);

    const FoamDictContext& ctx_;
    fs::path caseDir_;
    std::deque<Source> sources_;
    std::size_t bytes_ = 0, budget_;
};

[[noreturn]] void unsupported(const Token& t)
{
    const std::string name = t.text;
    if (name == "#calc" || name == "#eval" || name == "#codeStream")
        fail(where(t) + ": " + name + " needs OpenFOAM to compile code: not supported (write the value out)");
    fail(where(t) + ": unsupported directive " + (name == "#" ? std::string("'#'") : name));
}

std::string Expander::expandString(const Dict& scope, const std::string& s, const Token& at)
{
    std::string out;
    for (std::size_t i = 0; i < s.size();) {
        if (s[i] != '$') {
            out += s[i++];
            continue;
        }
        std::string name;
        std::size_t j = i + 1;
        if (j < s.size() && s[j] == '{') {
            const std::size_t e = s.find('}', j);
            if (e == std::string::npos) fail(where(at) + ": unterminated ${ in " + q(s));
            name = s.substr(j + 1, e - j - 1);
            j = e + 1;
        } else {
            while (j < s.size() && (std::isalnum(static_cast<unsigned char>(s[j])) || s[j] == '_')) ++j;
            name = s.substr(i + 1, j - i - 1);
        }
        i = j;
        if (name == "FOAM_CASE") {
            out += caseDir_.string();
        } else if (name == "FOAM_CASENAME") {
            out += caseDir_.filename().string();
        } else if (const Entry* e = lookup(scope, name, at); e && !e->dict) {
            for (std::size_t k = 0; k < e->value.size(); ++k) out += (k ? " " : "") + unquote(e->value[k].text);
        } else if (const char* env = name.empty() ? nullptr : std::getenv(name.c_str())) {
            out += env;
        } else {
            fail(where(at) + ": $" + name + " in " + q(s) + " is neither an entry nor an environment variable");
        }
    }
    return out;
}

std::optional<fs::path> Expander::findEtc(const std::string& name) const
{
    std::error_code ec;
    for (const auto& dir : ctx_.etcDirs)
        if (fs::is_regular_file(dir / name, ec)) return dir / name;
    return std::nullopt;
}

fs::path Expander::resolveInclude(const Dict& scope, const Token& directive, const Token& arg)
{
    std::string name = expandString(scope, unquote(arg.text), arg);
    const auto tag = [&](const std::string& t) { return name.rfind(t, 0) == 0; };
    if (tag("<case>")) return caseDir_ / fs::path(name.substr(6)).relative_path();
    if (tag("<system>")) return caseDir_ / "system" / fs::path(name.substr(8)).relative_path();
    if (tag("<constant>")) return caseDir_ / "constant" / fs::path(name.substr(10)).relative_path();
    if (tag("<etc>/") || tag("~OpenFOAM/")) {
        const std::string rest = name.substr(name.find('/') + 1);
        if (auto f = findEtc(rest)) return *f;
        return fs::path(ctx_.etcDirs.empty() ? fs::path("<etc>") : ctx_.etcDirs.front()) / rest;
    }
    if (tag("~/")) {
        const char* home = std::getenv("HOME");
        if (!home) fail(where(directive) + ": " + directive.text + " " + arg.text + ": $HOME is not set");
        return fs::path(home) / name.substr(2);
    }
    fs::path p(name);
    if (p.is_relative() && arg.src && !arg.src->file.empty()) p = arg.src->file.parent_path() / p;
    return p;
}

std::optional<const Source*> Expander::includeSource(const Dict& scope, Lexer& lx, const Token& directive,
                                                     int fileDepth)
{
    const std::string& name = directive.text;
    const Token arg = lx.next();
    if (arg.kind != Tok::String && arg.kind != Tok::Word)
        fail(where(directive) + ": " + name + " expects a file name, found " +
             (arg.kind == Tok::End ? std::string("the end of the file") : q(arg.text)));
    if (fileDepth >= kMaxIncludeDepth)
        fail(where(directive) + ": " + name + " " + arg.text + ": includes nested more than " +
             std::to_string(kMaxIncludeDepth) + " deep (does a file include itself?)");
    const bool optional = name == "#sinclude" || name == "#includeIfPresent" || name == "#sincludeEtc";
    if (name == "#includeEtc" || name == "#sincludeEtc") {
        const std::string etcName = expandString(scope, unquote(arg.text), arg);
        if (auto f = findEtc(etcName)) {
            if (auto text = readWholeFile(*f)) return &addSource(*f, std::move(*text));
        } else if (fs::path(etcName).lexically_normal() == "caseDicts/setConstraintTypes") {
            return &addSource("<licvdb: caseDicts/setConstraintTypes>", foamConstraintTypesDict());
        }
        if (optional) return std::nullopt;
        fail(where(directive) + ": " + name + " " + arg.text + ": not found in " +
             (ctx_.etcDirs.empty() ? std::string("any OpenFOAM etc directory (none found: set WM_PROJECT_DIR "
                                                 "or install OpenFOAM)")
                                   : joinPaths(ctx_.etcDirs)));
    }
    const fs::path file = resolveInclude(scope, directive, arg);
    if (auto text = readWholeFile(file)) return &addSource(file, std::move(*text));
    if (optional) return std::nullopt;
    fail(where(directive) + ": " + name + " " + arg.text + ": cannot open " + file.string());
}

void Expander::appendDictTokens(const Dict& d, const Token& at, std::vector<Token>& out, int depth)
{
    if (depth > kMaxDictDepth) fail(where(at) + ": dictionaries nested too deep");
    const auto push = [&](Tok kind, std::string text) {
        Token t = at;
        t.kind = kind;
        t.sep = ' ';
        charge(text.size() + 1);
        t.text = std::move(text);
        out.push_back(std::move(t));
    };
    for (const auto& e : d.entries) {
        push(e->pattern ? Tok::String : Tok::Word, e->pattern ? q(e->key) : e->key);
        if (e->dict) {
            push(Tok::Punct, "{");
            appendDictTokens(*e->dict, at, out, depth + 1);
            push(Tok::Punct, "}");
        } else {
            for (const Token& v : e->value) {
                charge(v.text.size() + 1);
                out.push_back(v);
            }
            push(Tok::Punct, ";");
        }
    }
}

void Expander::expandVariable(const Dict& scope, const Token& var, std::vector<Token>& out)
{
    std::string name = var.text.substr(1);
    if (name.size() >= 2 && name.front() == '{' && name.back() == '}')
        name = expandString(scope, name.substr(1, name.size() - 2), var);
    if (name.empty()) fail(where(var) + ": '$' without a name");
    const std::size_t first = out.size();
    if (const Entry* e = lookup(scope, name, var)) {
        if (e->dict) {
            appendDictTokens(*e->dict, var, out, 0);
        } else {
            for (const Token& v : e->value) {
                charge(v.text.size() + 1);
                out.push_back(v);
            }
        }
    } else if (const char* env = std::getenv(name.c_str()); env && *env) {
        const Source& s = addSource(var.src ? var.src->file : fs::path(), env);
        Lexer lx(s);
        for (Token t = lx.next(); t.kind != Tok::End; t = lx.next()) {
            t.line = var.line;
            charge(t.text.size() + 1);
            out.push_back(std::move(t));
        }
    } else {
        fail(where(var) + ": " + var.text + " is not defined (no such entry above it, nor environment variable)");
    }
    if (out.size() > first) out[first].sep = var.sep;
}

void Expander::readValue(const Dict& scope, Lexer& lx, std::vector<Token>& out, int fileDepth)
{
    int depth = 0;
    const int startLine = lx.peek().line;
    for (;;) {
        Token t = lx.next();
        if (t.kind == Tok::End) {
            if (depth != 0) fail(where(t) + ": unbalanced ( or { in the entry that starts on line " +
                                 std::to_string(startLine));
            return;
        }
        if (t.is(';') && depth == 0) return;
        if (t.is('(') || t.is('{')) ++depth;
        if (t.is(')') || t.is('}')) {
            if (--depth < 0) fail(where(t) + ": unexpected '" + t.text + "' (a missing ';' before it?)");
        }
        if (t.kind == Tok::Variable) {
            expandVariable(scope, t, out);
        } else if (t.kind == Tok::Directive) {
            if (t.text == "#includeFunc") {
                lx.skipLine();
            } else if (isInclude(t.text)) {
                if (auto src = includeSource(scope, lx, t, fileDepth)) {
                    Lexer inner(**src);
                    const std::size_t first = out.size();
                    readValue(scope, inner, out, fileDepth + 1);
                    if (out.size() > first) out[first].sep = t.sep;
                }
            } else {
                unsupported(t);
            }
        } else {
            charge(t.text.size() + 1);
            out.push_back(std::move(t));
        }
    }
}

void Expander::mergeVariable(Dict& d, const Token& t, int dictDepth)
{
    std::string name = t.text.substr(1);
    if (name.size() >= 2 && name.front() == '{' && name.back() == '}')
        name = expandString(d, name.substr(1, name.size() - 2), t);
    const Entry* e = lookup(d, name, t);
    if (!e) fail(where(t) + ": " + t.text + " is not defined (used as a keyword: a dictionary to merge)");
    if (!e->dict) fail(where(t) + ": " + t.text + " is not a dictionary (used as a keyword: a dictionary to merge)");
    const auto copy = cloneDict(*e->dict, &d, dictDepth);
    for (auto& sub : copy->entries) {
        charge(sub->key.size() + 16);
        addEntry(d, std::move(sub), Mode::Merge, dictDepth);
    }
}

void Expander::removeEntries(Dict& d, Lexer& lx)
{
    const Token arg = lx.next();
    std::vector<Entry> keys; // matchers
    const auto addKey = [&](const Token& k) {
        Entry m;
        m.pattern = k.kind == Tok::String;
        m.key = m.pattern ? unquote(k.text) : k.text;
        keys.push_back(std::move(m));
    };
    if (arg.kind == Tok::Word || arg.kind == Tok::String) {
        addKey(arg);
    } else if (arg.kind == Tok::Raw) {
        for (const auto& w : listWords({arg})) addKey(Token{Tok::Word, w});
    } else if (arg.is('(')) {
        for (Token k = lx.next(); !k.is(')'); k = lx.next()) {
            if (k.kind == Tok::End) fail(where(arg) + ": #remove: unterminated list");
            if (k.kind == Tok::Word || k.kind == Tok::String) addKey(k);
        }
    } else {
        fail(where(arg) + ": #remove expects a keyword or a list of keywords");
    }
    std::vector<const Entry*> doomed;
    for (const auto& e : d.entries)
        for (const auto& k : keys)
            if (k.matches(e->key)) {
                doomed.push_back(e.get());
                break;
            }
    for (const Entry* e : doomed) d.remove(e);
}

/// A directive where an entry's keyword stands. False: none (the caller reads an entry).
bool Expander::directiveAtKeyword(Dict& d, Lexer& lx, const Token& t, int dictDepth, int fileDepth, Mode& mode)
{
    const std::string& n = t.text;
    if (isInclude(n)) {
        if (auto src = includeSource(d, lx, t, fileDepth)) {
            Lexer inner(**src);
            parseEntries(d, inner, dictDepth, fileDepth + 1, false, true);
        }
    } else if (n == "#includeFunc" || n == "#includeFuncIfPresent") {
        lx.skipLine();
    } else if (n == "#inputMode") {
        lx.next();
    } else if (n == "#remove") {
        removeEntries(d, lx);
    } else if (n == "#default") {
        mode = Mode::Default;
        return false;
    } else if (n == "#overwrite") {
        mode = Mode::Overwrite;
        return false;
    } else if (n == "#merge" || n == "#warn" || n == "#error") {
        mode = Mode::Merge;
        return false;
    } else {
        unsupported(t);
    }
    return true;
}

void Expander::parseEntries(Dict& d, Lexer& lx, int dictDepth, int fileDepth, bool subDict, bool includedFile)
{
    if (dictDepth > kMaxDictDepth)
        fail(where(lx.peek()) + ": dictionaries nested more than " + std::to_string(kMaxDictDepth) + " deep");
    Mode mode = Mode::Merge;
    for (;;) {
        Token t = lx.next();
        if (t.kind == Tok::End) {
            if (subDict) fail(where(t) + ": missing '}' at the end of the file");
            return;
        }
        if (t.is(';')) continue;
        if (t.is('}')) {
            if (subDict) return;
            fail(where(t) + ": unexpected '}'");
        }
        if (t.kind == Tok::Verbatim) continue;
        if (t.kind == Tok::Directive) {
            if (directiveAtKeyword(d, lx, t, dictDepth, fileDepth, mode)) mode = Mode::Merge;
            continue;
        }
        if (t.kind == Tok::Variable) {
            mergeVariable(d, t, dictDepth);
            continue;
        }
        if (t.kind != Tok::Word && t.kind != Tok::String)
            fail(where(t) + ": expected a keyword, found " + q(t.text.substr(0, 40)));
        auto e = std::make_unique<Entry>();
        e->pattern = t.kind == Tok::String;
        e->key = e->pattern ? unquote(t.text) : t.text;
        e->src = t.src;
        e->line = t.line;
        charge(e->key.size() + 16);
        if (lx.peek().is('{')) {
            lx.next();
            e->dict = std::make_unique<Dict>();
            e->dict->parent = &d;
            parseEntries(*e->dict, lx, dictDepth + 1, fileDepth, true, false);
        } else {
            readValue(d, lx, e->value, fileDepth);
        }
        if (includedFile && e->key == "FoamFile" && !e->pattern) {
            mode = Mode::Merge; // an included file's header is not an entry (dictionary::read)
            continue;
        }
        if (mode == Mode::Overwrite) {
            if (Entry* old = d.findLiteral(e->key)) d.remove(old);
        }
        addEntry(d, std::move(e), mode == Mode::Default ? Mode::Default : Mode::Merge, dictDepth);
        mode = Mode::Merge;
    }
}

// ---- boundaryField ------------------------------------------------------------------------------

/// The entry OpenFOAM's GeometricBoundaryField::readField gives `patch`: its name, a group (the
/// last group entry first), then (unless the patch is empty) the last "regex" key that matches.
const Entry* patchEntry(const Dict& bf, const FoamPatch& patch)
{
    if (const Entry* e = bf.findLocal(patch.name, false); e && e->dict && !e->pattern) return e;
    for (auto it = bf.entries.rbegin(); it != bf.entries.rend(); ++it) {
        const Entry& e = **it;
        if (e.dict && !e.pattern && std::find(patch.groups.begin(), patch.groups.end(), e.key) != patch.groups.end())
            return &e;
    }
    if (patch.type == "empty") return nullptr;
    if (const Entry* e = bf.findLocal(patch.name, true); e && e->dict) return e;
    return nullptr;
}

std::vector<Token> wordTokens(const std::vector<std::string>& words, const Source* src, int line)
{
    std::vector<Token> out;
    for (const auto& w : words) out.push_back(Token{Tok::Word, w, ' ', src, line});
    return out;
}

void Expander::rewriteBoundary(Dict& root)
{
    Entry* bf = root.findLiteral("boundaryField");
    if (!bf || !bf->dict || ctx_.patches.empty()) return;
    const Entry* internal = root.findLiteral("internalField");
    const bool uniform = internal && !internal->dict && !internal->value.empty() && internal->value[0].text == "uniform";
    auto out = std::make_unique<Dict>();
    out->parent = &root;
    for (const FoamPatch& patch : ctx_.patches) {
        const Entry* src = patchEntry(*bf->dict, patch);
        std::unique_ptr<Entry> e;
        if (src) {
            e = cloneEntry(*src, out.get(), 1);
        } else if (isConstraintType(patch.type)) {
            e = std::make_unique<Entry>();
            e->dict = std::make_unique<Dict>();
            auto type = std::make_unique<Entry>();
            type->key = "type";
            type->value = wordTokens({patch.type}, bf->src, bf->line);
            e->dict->literal["type"] = type.get();
            e->dict->entries.push_back(std::move(type));
            if (constraintWithValue(patch.type) && uniform) {
                auto value = std::make_unique<Entry>();
                value->key = "value";
                value->value = internal->value;
                e->dict->literal["value"] = value.get();
                e->dict->entries.push_back(std::move(value));
            }
        } else {
            std::string groups;
            for (const auto& g : patch.groups) groups += (groups.empty() ? "" : " ") + g;
            fail(where(bf->src, bf->line) + ": boundaryField has no entry for patch " + q(patch.name) + " (type " +
                 patch.type + (groups.empty() ? "" : ", groups " + groups) +
                 "): OpenFOAM would not read this field either");
        }
        e->key = patch.name;
        e->pattern = false;
        charge(e->key.size() + 64);
        addEntry(*out, std::move(e), Mode::Overwrite, 1);
    }
    out->reparent();
    bf->dict = std::move(out);
}

// ---- writing ----------------------------------------------------------------------------------

void writeValue(std::string& out, const std::vector<Token>& value)
{
    for (std::size_t i = 0; i < value.size(); ++i) {
        const char sep = i == 0 ? ' ' : value[i].sep;
        if (sep) out += sep;
        out += value[i].text;
    }
}

void writeDict(std::string& out, const Dict& d, int indent, bool headerFirst)
{
    const std::string pad(std::size_t(std::min(indent, 16)) * 4, ' ');
    std::vector<const Entry*> order;
    if (headerFirst)
        if (const Entry* h = d.findLocal("FoamFile", false)) order.push_back(h);
    for (const auto& e : d.entries)
        if (order.empty() || e.get() != order.front()) order.push_back(e.get());
    for (const Entry* e : order) {
        out += pad;
        out += e->pattern ? q(e->key) : e->key;
        if (e->dict) {
            out += "\n" + pad + "{\n";
            writeDict(out, *e->dict, indent + 1, false);
            out += pad + "}\n";
        } else {
            writeValue(out, e->value);
            out += ";\n";
        }
        if (indent == 0) out += "\n";
    }
}

/// Binary data in the text (a `format binary` field's lists: raw doubles always hold control bytes).
/// A `format binary` header over text only (hand-written tutorial fields have it) is text.
bool isBinary(std::string_view text)
{
    return std::any_of(text.begin(), text.end(), [](char ch) {
        const auto c = static_cast<unsigned char>(ch);
        return c < 0x09 || (c > 0x0d && c < 0x20) || c == 0x7f;
    });
}

std::unique_ptr<Dict> parseRoot(Expander& ex, const Source& src)
{
    auto root = std::make_unique<Dict>();
    Lexer lx(src);
    ex.parseEntries(*root, lx, 0, 0, false, false);
    return root;
}

/// Whether a `$` token stands where VTK 9.1 reads it: `key $name;` or a `$name` merge.
bool vtkReadsVariable(const Token& var, const Token* prev, const Token* prevPrev, const Token& next)
{
    const std::string name = var.text.substr(1);
    if (name.empty() || name.find_first_of(".:/{^") != std::string::npos) return false;
    const auto boundary = [](const Token* t) { return !t || t->is(';') || t->is('{') || t->is('}'); };
    if (boundary(prev)) return true; // a merge
    return (prev->kind == Tok::Word || prev->kind == Tok::String) && boundary(prevPrev) && next.is(';');
}

} // namespace

std::string foamConstraintTypesDict()
{
    std::string out = "// caseDicts/setConstraintTypes as OpenFOAM ships it (written by licvdb: no OpenFOAM etc found)\n";
    for (const auto& type : constraintTypes()) {
        out += type + "\n{\n    type " + type + ";\n";
        if (constraintWithValue(type)) out += "    value $internalField;\n";
        out += "}\n";
    }
    return out;
}

std::vector<fs::path> foamEtcDirs()
{
    std::vector<fs::path> dirs;
    std::error_code ec;
    const auto add = [&](const fs::path& p) {
        if (!p.empty() && fs::is_directory(p, ec) && std::find(dirs.begin(), dirs.end(), p) == dirs.end())
            dirs.push_back(p);
    };
    const auto newestFirst = [&](const fs::path& parent, const std::string& prefix, const fs::path& sub) {
        std::vector<fs::path> found;
        for (fs::directory_iterator it(parent, ec), end; !ec && it != end; it.increment(ec))
            if (it->path().filename().string().rfind(prefix, 0) == 0) found.push_back(it->path() / sub);
        std::sort(found.rbegin(), found.rend());
        for (const auto& f : found) add(f);
    };
    if (const char* home = std::getenv("HOME"); home && *home) {
        const fs::path user = fs::path(home) / ".OpenFOAM";
        if (const char* api = std::getenv("WM_PROJECT_VERSION"); api && *api) add(user / api);
        add(user);
    }
    if (const char* site = std::getenv("WM_PROJECT_SITE"); site && *site) add(fs::path(site) / "etc");
    if (const char* dir = std::getenv("WM_PROJECT_DIR"); dir && *dir) add(fs::path(dir) / "etc");
    add("/usr/share/openfoam/etc");
    newestFirst("/usr/lib/openfoam", "openfoam", "etc");
    newestFirst("/opt", "openfoam", "etc");
    newestFirst("/opt", "OpenFOAM", "etc");
    return dirs;
}

bool needsFoamExpansion(std::string_view text, const std::vector<FoamPatch>& patches)
{
    if (isBinary(text)) return false;
    try {
        Source src{fs::path(), std::string(text)};
        Lexer lx(src);
        std::optional<Token> prev, prevPrev;
        for (Token t = lx.next(); t.kind != Tok::End; t = lx.next()) {
            if (t.kind == Tok::Directive && t.text != "#inputMode") return true;
            if (t.kind == Tok::Variable &&
                !vtkReadsVariable(t, prev ? &*prev : nullptr, prevPrev ? &*prevPrev : nullptr, lx.peek()))
                return true;
            prevPrev = std::move(prev);
            prev = std::move(t);
        }
        FoamDictContext ctx;
        Expander ex(ctx, text.size());
        const auto root = parseRoot(ex, src); // malformed: an InputError, below
        if (patches.empty()) return false;
        const Entry* bf = root->findLocal("boundaryField", false);
        if (!bf || !bf->dict) return false;
        for (const FoamPatch& p : patches) // VTK 9.1: the patch's name or a regex key, nothing else
            if (const Entry* e = bf->dict->findLocal(p.name, true); !e || !e->dict) return true;
        return false;
    } catch (const lic::InputError&) {
        return true;
    }
}

std::string expandFoamDictionary(std::string_view text, const FoamDictContext& ctx)
{
    if (isBinary(text))
        fail((ctx.file.empty() ? std::string("<dictionary>") : ctx.file.string()) +
             ": a binary OpenFOAM file: its directives cannot be expanded (OpenFOAM writes binary files expanded)");
    Expander ex(ctx, text.size());
    const Source& src = ex.addSource(ctx.file, std::string(text));
    const auto root = parseRoot(ex, src);
    ex.rewriteBoundary(*root);
    std::string out = "// expanded by licvdb";
    if (!ctx.file.empty()) out += " from " + ctx.file.string();
    out += "\n";
    writeDict(out, *root, 0, true);
    return out;
}

namespace {

void normalised(std::string& out, const std::string& text)
{
    for (const char c : text) {
        const bool paren = c == '(' || c == ')' || c == '[' || c == ']';
        if (isSpace(c) || paren) {
            if (!out.empty() && out.back() != ' ') out += ' ';
            if (paren) out += std::string(1, c) + ' ';
        } else {
            out += c;
        }
    }
}

void flatten(const Dict& d, const std::string& prefix, std::vector<std::pair<std::string, std::string>>& out)
{
    for (const auto& e : d.entries) {
        const std::string key = prefix + (e->pattern ? q(e->key) : e->key);
        if (e->dict) {
            flatten(*e->dict, key + "/", out);
            continue;
        }
        std::string value;
        for (const Token& t : e->value) {
            if (t.kind == Tok::String || t.kind == Tok::Verbatim) {
                if (!value.empty() && value.back() != ' ') value += ' ';
                value += t.text;
            } else {
                normalised(value, " " + t.text + " ");
            }
        }
        while (!value.empty() && value.back() == ' ') value.pop_back();
        out.emplace_back(key, value.substr(value.empty() || value[0] != ' ' ? 0 : 1));
    }
}

} // namespace

std::vector<std::pair<std::string, std::string>> foamDictionaryEntries(std::string_view text, const FoamDictContext& ctx)
{
    if (isBinary(text))
        fail((ctx.file.empty() ? std::string("<dictionary>") : ctx.file.string()) + ": a binary OpenFOAM file");
    Expander ex(ctx, text.size());
    const Source& src = ex.addSource(ctx.file, std::string(text));
    const auto root = parseRoot(ex, src);
    ex.rewriteBoundary(*root);
    std::vector<std::pair<std::string, std::string>> out;
    flatten(*root, "", out);
    return out;
}

std::vector<FoamPatch> readFoamBoundary(const fs::path& boundaryFile)
{
    if (boundaryFile.extension() == ".gz") return {};
    auto text = readWholeFile(boundaryFile);
    if (!text) fail(boundaryFile.string() + ": cannot read the OpenFOAM boundary file");
    if ((text->size() >= 2 && static_cast<unsigned char>((*text)[0]) == 0x1f &&
         static_cast<unsigned char>((*text)[1]) == 0x8b) ||
        isBinary(*text))
        return {};
    FoamDictContext ctx;
    ctx.file = boundaryFile;
    Expander ex(ctx, text->size());
    const Source& src = ex.addSource(boundaryFile, std::move(*text));
    Lexer lx(src);
    // FoamFile { … }, then [N] ( name { … } … )
    Token t = lx.next();
    if (t.kind == Tok::Word && t.text == "FoamFile" && lx.peek().is('{')) {
        Dict header;
        lx.next();
        ex.parseEntries(header, lx, 1, 0, true, false);
        t = lx.next();
    }
    if (t.kind == Tok::Word && !t.text.empty() && std::isdigit(static_cast<unsigned char>(t.text[0]))) t = lx.next();
    if (t.kind == Tok::Raw) return {}; // a list without dictionaries: no patches
    if (!t.is('(')) fail(where(t) + ": expected the list of patches '(' in the boundary file");
    std::vector<FoamPatch> patches;
    for (t = lx.next(); !t.is(')'); t = lx.next()) {
        if (t.kind != Tok::Word && t.kind != Tok::String) fail(where(t) + ": expected a patch name in the boundary file");
        if (!lx.next().is('{')) fail(where(t) + ": expected '{' after patch " + q(t.text));
        Dict d;
        ex.parseEntries(d, lx, 1, 0, true, false);
        FoamPatch p;
        p.name = unquote(t.text);
        if (const Entry* type = d.findLocal("type", false); type && !type->dict && !type->value.empty())
            p.type = type->value[0].text;
        if (const Entry* g = d.findLocal("inGroups", false); g && !g->dict) p.groups = listWords(g->value);
        if ((isConstraintType(p.type) || p.type == "wall") &&
            std::find(p.groups.begin(), p.groups.end(), p.type) == p.groups.end())
            p.groups.push_back(p.type);
        patches.push_back(std::move(p));
    }
    return patches;
}

} // namespace vdbexport::mesh_module
