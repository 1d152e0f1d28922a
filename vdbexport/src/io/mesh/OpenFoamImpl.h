// The OpenFOAM reader's parts (Mesh.h: readOpenFoam, openFoamTimes), shared by its files only: a
// case's layout and times, at the top level and in processor*/ (OpenFoamTimes.cpp), and the shadow
// case a read goes through (OpenFoamCase.cpp). OpenFoam.cpp reads the shadow with VTK's reader.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace vdbexport::mesh_module::openfoam {

/// `items` joined by `sep`, at most `most` of them (then "… (N in all)"): for messages.
std::string joinedList(const std::vector<std::string>& items, const std::string& sep = ", ", std::size_t most = 12);

// ---- the case on disk (OpenFoamTimes.cpp) -----------------------------------------------------

/// The time value a directory name stands for: a plain decimal number ("0", "0.25", "1e-05").
std::optional<double> timeOfName(const std::string& name);

/// Where a time of a case is read from.
enum class From { Processors, TopLevel, Incomplete };

struct FoamTime
{
    double value = 0;
    From from = From::TopLevel;
    std::optional<std::string> topName;          ///< its directory at the top level
    std::vector<std::string> procNames;          ///< its directory in each processor ("" where missing)
};

struct FoamCase
{
    std::filesystem::path dir;
    std::vector<std::string> processors; ///< processor0, processor1, … (by number)
    std::vector<FoamTime> times;         ///< sorted
};

/// The case of `path` (a case directory, its `case.foam` or its controlDict): its processor
/// directories and its times, each with where it is read from.
/// @throw lic::InputError for what is not a case, a processor directory, a collated decomposition.
FoamCase scanCase(const std::string& path);

/// The processor directories that have time `t` (`with`), or that lack it.
std::vector<std::string> processorsWith(const FoamCase& c, const FoamTime& t, bool with);

/// "2 processor directories".
std::string processorsText(const FoamCase& c);

/// Where time `t` is read from, for --list and notes.
std::string sourceText(const FoamCase& c, const FoamTime& t);

// ---- the shadow case (OpenFoamCase.cpp) -------------------------------------------------------

/// What a field directory of the read time holds, for the velocity check and the notes.
struct TimeFields
{
    std::vector<std::string> fields;   ///< field names (file names without .gz) linked or copied
    std::vector<std::string> vectors;  ///< those whose header class is a vector field
    std::vector<std::string> leftOut;  ///< "0/U.orig (object U)"
    std::vector<std::string> expanded; ///< "0/U"
};

/// A temporary directory, removed with everything in it when this goes.
class ShadowDir
{
public:
    ShadowDir();
    ~ShadowDir();
    ShadowDir(const ShadowDir&) = delete;
    ShadowDir& operator=(const ShadowDir&) = delete;
    const std::filesystem::path& path() const { return mPath; }

private:
    std::filesystem::path mPath;
};

/// The directory of `root` (the case, or a processor directory) whose polyMesh the time `timeName`
/// uses: the latest time directory up to it with a polyMesh/faces, else constant. Empty if none.
std::optional<std::string> meshInstance(const std::filesystem::path& root, double t);

/// Link `root`'s system/ and constant/ into `shadow`, the time directory the mesh comes from if
/// it is a time directory, and make the shadow of the time `timeName`.
void shadowRoot(const std::filesystem::path& root, const std::filesystem::path& shadow, const std::string& label,
                const std::string& timeName, const std::string& meshDir, const std::string& wanted,
                const std::vector<std::filesystem::path>& etcDirs, TimeFields& fields);

/// Replace the shadow's path by the case's in `text` (VTK's messages name the files it read).
std::string unshadow(std::string text, const std::filesystem::path& shadow, const std::filesystem::path& caseDir);

} // namespace vdbexport::mesh_module::openfoam
