// The dictionary tree of the OpenFOAM dictionary expander (FoamDictImpl.h) and the parser that
// builds it entry by entry, as OpenFOAM's dictionary::read does (so that a `$var` sees what
// OpenFOAM's sees at that point): dictionary entries merge, #remove, #default and #overwrite act on
// what is above them, quoted keys are regular expressions; directives where a keyword stands.
#include "io/mesh/FoamDictImpl.h"

#include <algorithm>
#include <cctype>
#include <cstdlib>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module::foam_dict {

namespace {

constexpr std::size_t kMinBudget = std::size_t(64) << 20;

[[noreturn]] void unsupported(const Token& t)
{
    const std::string name = t.text;
    if (name == "#calc" || name == "#eval" || name == "#codeStream")
        fail(where(t) + ": " + name + " needs OpenFOAM to compile code: not supported (write the value out)");
    fail(where(t) + ": unsupported directive " + (name == "#" ? std::string("'#'") : name));
}

} // namespace

// ---- dictionary tree --------------------------------------------------------------------------

bool Entry::matches(const std::string& name) const
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

// ---- parsing ----------------------------------------------------------------------------------

Expander::Expander(const FoamDictContext& ctx, std::size_t inputBytes)
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

const Source& Expander::addSource(fs::path file, std::string text)
{
    bytes_ += text.size();
    return sources_.emplace_back(Source{std::move(file), std::move(text)});
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
            fail(where(t) + ": expected a keyword, found " + dq(t.text.substr(0, 40)));
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

} // namespace vdbexport::mesh_module::foam_dict
