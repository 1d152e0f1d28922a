// OpenFOAM dictionaries expanded as OpenFOAM reads them (see FoamDict.h): the entry points. A
// text is lexed (FoamDictLexer.cpp, close to OpenFOAM's ISstream), built into a dictionary tree
// entry by entry (FoamDictParse.cpp, so `$var` sees what OpenFOAM's sees at that point) with
// OpenFOAM's scoped search (FoamDictVars.cpp) and its includes (FoamDictIncludes.cpp),
// boundaryField is matched to the patches (FoamDictBoundary.cpp, GeometricBoundaryField.C), and
// the tree is written back here as plain text for VTK's reader (or flattened, for tests).
#include "io/mesh/FoamDictImpl.h"

#include <algorithm>
#include <optional>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

bool foam_dict::isBinary(std::string_view text)
{
    return std::any_of(text.begin(), text.end(), [](char ch) {
        const auto c = static_cast<unsigned char>(ch);
        return c < 0x09 || (c > 0x0d && c < 0x20) || c == 0x7f;
    });
}

using namespace foam_dict;

namespace {

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
        out += e->pattern ? dq(e->key) : e->key;
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
        const std::string key = prefix + (e->pattern ? dq(e->key) : e->key);
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

// ---- reading ----------------------------------------------------------------------------------

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

} // namespace vdbexport::mesh_module
