// OpenFOAM dictionaries as OpenFOAM reads them, for VTK's reader (FoamDict*.cpp): the directives and
// macros that VTK 9.1's vtkOpenFOAMReader cannot read (#includeEtc, #includeFunc, scoped $:a.b and
// $../x, `uniform $var`) expanded the way OpenFOAM does, and boundaryField rewritten to one entry per
// patch (VTK does not match patch groups and drops a field's point data when a patch has no entry).
// Plain C++ (no VTK): also built into tests/unit/test_foam_dict and the fuzz_foam_dict target.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vdbexport::mesh_module {

/// A patch of constant/polyMesh/boundary. `groups` are its inGroups, plus its own type when that is
/// a constraint type or `wall` (OpenFOAM's polyPatch adds those groups itself).
struct FoamPatch
{
    std::string name, type;
    std::vector<std::string> groups;
};

struct FoamDictContext
{
    std::filesystem::path file;                 // the dictionary's own path: relative #include, messages
    std::vector<std::filesystem::path> etcDirs; // where #includeEtc looks, in order
    std::vector<FoamPatch> patches;             // empty: boundaryField left as written
    /// The case directory for $FOAM_CASE, $FOAM_CASENAME and <case>/<system>/<constant> in include
    /// paths. Empty: the directory above the file's own (CASE for CASE/0/U), and above a
    /// processor<N> directory (CASE for CASE/processor0/0/U), as OpenFOAM's parallel runs set it.
    std::filesystem::path caseDir;
};

/// OpenFOAM's #includeEtc search path for a case, existing directories only, in OpenFOAM's order
/// (user, site, project: the first that has the file wins): ~/.OpenFOAM/<version> and ~/.OpenFOAM,
/// $WM_PROJECT_SITE/etc, $WM_PROJECT_DIR/etc if set, then the usual install paths
/// (/usr/share/openfoam/etc, /usr/lib/openfoam/openfoam*/etc, /opt/openfoam*/etc; newest first).
std::vector<std::filesystem::path> foamEtcDirs();

/// Whether `text` uses something VTK 9.1's reader cannot read: a directive other than #inputMode
/// (any #include counts: the included file is not looked at here), a scoped or embedded `$var`
/// (anything but `key $name;` and a `$name;` dictionary merge), or, with `patches`, a boundaryField
/// without an entry (by name or "regex") for every patch. False for binary data (the lists of a
/// `format binary` field: solver output, no directives; a `format binary` header over plain text,
/// as some tutorials have, is text); true for text that does not parse (the expansion says where).
bool needsFoamExpansion(std::string_view text, const std::vector<FoamPatch>& patches = {});

/// The dictionary with #include/#sinclude/#includeIfPresent/#includeEtc expanded (recursively, at
/// most 16 files deep), #includeFunc dropped, #inputMode ignored, #remove and #default/#overwrite
/// applied, $var / ${var} / $:a.b / $a.b / $../x substituted where they stand (also inside entries:
/// `uniform $flowVelocity`) with OpenFOAM's scoping, and, when `patches` are given, boundaryField
/// rewritten to one entry per patch, chosen as OpenFOAM's GeometricBoundaryField::readField does:
/// the entry named like the patch, else a group's entry (the last one written wins), else (an
/// `empty` patch: `{ type empty; }`) the last "regex" key that matches; a constraint-type patch with
/// none gets `{ type <its type>; }` (a `value` too where setConstraintTypes gives one); any other
/// patch without an entry is an error, as in OpenFOAM. A missing caseDicts/setConstraintTypes is
/// replaced by its content (foamConstraintTypesDict()), so tutorial fields read without OpenFOAM.
/// The FoamFile header stays first; comments are dropped; values keep their spacing.
/// @throw lic::InputError naming the file and line ("…/0/U:23: #includeEtc \"caseDicts/x\": not
/// found in …") for #calc/#eval/#codeStream/#if and unknown directives, a missing #include or
/// #includeEtc file, an undefined $var, binary data and malformed text (unbalanced braces,
/// unterminated strings, nesting deeper than 64 levels, an expansion that would hold more than
/// 64 MiB or 32x the input in tokens).
std::string expandFoamDictionary(std::string_view text, const FoamDictContext& ctx);

/// constant/polyMesh/boundary's patches (ASCII; for a compressed boundary file or one with binary
/// data: empty).
/// @throw lic::InputError for a file that cannot be read or does not parse (file:line).
std::vector<FoamPatch> readFoamBoundary(const std::filesystem::path& boundaryFile);

/// The primitive entries of the expanded dictionary (expandFoamDictionary's rules), flattened in
/// order: {"FoamFile/object", "U"}, {"boundaryField/inlet/value", "uniform ( 1 0 0 )"}: keys joined
/// by '/', value tokens separated by one space (parentheses and brackets too), no ';'. For tests,
/// and for reading a header or a few values without VTK.
/// @throw lic::InputError as expandFoamDictionary.
std::vector<std::pair<std::string, std::string>> foamDictionaryEntries(std::string_view text,
                                                                       const FoamDictContext& ctx);

/// What OpenFOAM's etc/caseDicts/setConstraintTypes says (one entry per constraint patch type,
/// `value $internalField` for cyclicACMI, processor and processorCyclic): used when no etc
/// directory has the file.
std::string foamConstraintTypesDict();

} // namespace vdbexport::mesh_module
