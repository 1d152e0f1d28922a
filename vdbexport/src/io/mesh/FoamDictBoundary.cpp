// boundaryField in the OpenFOAM dictionary expander (FoamDictImpl.h): rewritten to one entry per
// patch as OpenFOAM's GeometricBoundaryField::readField chooses it (VTK does not match patch groups
// and drops a field's point data when a patch has no entry), for the patches, with their types and
// groups, of constant/polyMesh/boundary (readFoamBoundary); and the constraint patch types that
// caseDicts/setConstraintTypes lists (foamConstraintTypesDict).
#include "io/mesh/FoamDictImpl.h"

#include <algorithm>
#include <cctype>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

namespace foam_dict {

namespace {

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

bool isConstraintType(const std::string& type)
{
    const auto& t = constraintTypes();
    return std::find(t.begin(), t.end(), type) != t.end();
}

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

} // namespace

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
            fail(where(bf->src, bf->line) + ": boundaryField has no entry for patch " + dq(patch.name) + " (type " +
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

} // namespace foam_dict

using namespace foam_dict;

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
        if (!lx.next().is('{')) fail(where(t) + ": expected '{' after patch " + dq(t.text));
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
