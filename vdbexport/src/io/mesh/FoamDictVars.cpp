// $variables of the OpenFOAM dictionary expander (FoamDictImpl.h): OpenFOAM's scoped search
// (dictionarySearch.C: `$a`, `$a.b`, `$:a.b`, `$../x`, `$/a/b`) over what is parsed so far, a
// variable's value put where it stands (also inside an entry: `uniform $flowVelocity`), a `$dict`
// keyword merged, and `$var` / `${var}` inside #include names ($FOAM_CASE, the environment).
#include "io/mesh/FoamDictImpl.h"

#include <cctype>
#include <cstdlib>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module::foam_dict {

namespace {

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

} // namespace

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
            if (e == std::string::npos) fail(where(at) + ": unterminated ${ in " + dq(s));
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
            for (std::size_t k = 0; k < e->value.size(); ++k) {
                if (k) out += ' ';
                out += unquote(e->value[k].text);
            }
        } else if (const char* env = name.empty() ? nullptr : std::getenv(name.c_str())) {
            out += env;
        } else {
            fail(where(at) + ": $" + name + " in " + dq(s) + " is neither an entry nor an environment variable");
        }
    }
    return out;
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
        push(e->pattern ? Tok::String : Tok::Word, e->pattern ? dq(e->key) : e->key);
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

} // namespace vdbexport::mesh_module::foam_dict
