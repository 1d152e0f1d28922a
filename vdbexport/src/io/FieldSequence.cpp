#include "vdbexport/io/FieldSequence.h"

#include "lic/util/Error.h"

#include <algorithm>
#include <filesystem>
#include <regex>
#include <set>

namespace vdbexport {

namespace fs = std::filesystem;

namespace {

struct Placeholder
{
    std::size_t pos = std::string::npos, len = 0;
    int width = 0; ///< zero-padded digits (0 = as many as needed)
};

/// Placeholders in the file-name part of `path` (directories may contain `#` or `%` freely).
std::vector<Placeholder> placeholders(const std::string& path)
{
    const std::size_t nameStart = path.find_last_of('/') == std::string::npos ? 0 : path.find_last_of('/') + 1;
    std::vector<Placeholder> out;
    static const std::regex printfRe("%(0?)([0-9]*)d");
    for (std::size_t i = nameStart; i < path.size();) {
        if (path[i] == '#') {
            std::size_t j = i;
            while (j < path.size() && path[j] == '#') ++j;
            out.push_back({i, j - i, int(j - i)});
            i = j;
            continue;
        }
        if (path[i] == '%') {
            std::smatch m;
            const std::string rest = path.substr(i);
            if (std::regex_search(rest, m, printfRe, std::regex_constants::match_continuous)) {
                const int width = m[2].length() ? std::stoi(m[2].str()) : 0;
                if (width > 9) throw lic::InputError("field pattern \"" + path + "\": %" + m[1].str() + m[2].str() + "d is too wide");
                out.push_back({i, std::size_t(m.length(0)), width});
                i += std::size_t(m.length(0));
                continue;
            }
        }
        ++i;
    }
    return out;
}

Placeholder onePlaceholder(const std::string& pattern)
{
    const auto ph = placeholders(pattern);
    if (ph.empty()) {
        throw lic::InputError("field \"" + pattern + "\" is not a frame pattern: put a run of # (or %04d) where the "
                              "frame number goes, e.g. cache/data/fluid_data_####.vdb");
    }
    if (ph.size() > 1) throw lic::InputError("field pattern \"" + pattern + "\" has more than one frame-number placeholder");
    return ph.front();
}

std::string padded(int frame, int width)
{
    std::string digits = std::to_string(frame);
    if (int(digits.size()) < width) digits.insert(0, std::size_t(width) - digits.size(), '0');
    return digits;
}

} // namespace

bool isFramePattern(const std::string& path) { return !placeholders(path).empty(); }

std::string expandFramePattern(const std::string& pattern, int frame)
{
    const Placeholder ph = onePlaceholder(pattern);
    return pattern.substr(0, ph.pos) + padded(frame, ph.width) + pattern.substr(ph.pos + ph.len);
}

FieldFrames resolveFieldFrames(const FieldSpec& field)
{
    const Placeholder ph = onePlaceholder(field.path);
    FieldFrames out;
    if (field.frames) {
        const auto [first, last] = *field.frames;
        std::vector<int> missing;
        for (int f = first; f <= last; ++f) {
            out.numbers.push_back(f);
            out.paths.push_back(expandFramePattern(field.path, f));
            std::error_code ec;
            if (!fs::is_regular_file(out.paths.back(), ec)) missing.push_back(f);
        }
        if (!missing.empty()) {
            throw lic::InputError("field sequence \"" + field.path + "\": " + std::to_string(missing.size()) + " of " +
                                  std::to_string(out.numbers.size()) + " frames are missing, the first is frame " +
                                  std::to_string(missing.front()) + " (\"" + expandFramePattern(field.path, missing.front()) + "\")");
        }
        return out;
    }
    // No range given: every frame of the pattern on disk.
    const fs::path dir = fs::path(field.path.substr(0, ph.pos)).parent_path();
    const std::string name = fs::path(field.path).filename().string();
    const std::size_t namePos = ph.pos - (field.path.size() - name.size());
    const std::string prefix = name.substr(0, namePos), suffix = name.substr(namePos + ph.len);
    std::set<int> found;
    std::error_code ec;
    const fs::path scan = dir.empty() ? fs::path(".") : dir;
    for (const auto& e : fs::directory_iterator(scan, ec)) {
        const std::string n = e.path().filename().string();
        if (n.size() <= prefix.size() + suffix.size() || n.compare(0, prefix.size(), prefix) != 0 ||
            n.compare(n.size() - suffix.size(), suffix.size(), suffix) != 0)
            continue;
        const std::string digits = n.substr(prefix.size(), n.size() - prefix.size() - suffix.size());
        if (digits.empty() || digits.size() > 9 || !std::all_of(digits.begin(), digits.end(), ::isdigit)) continue;
        if (ph.width > 0 && int(digits.size()) < ph.width) continue;
        const int f = std::stoi(digits);
        if (expandFramePattern(field.path, f) == (dir / n).string()) found.insert(f);
    }
    if (found.empty()) {
        throw lic::InputError("field sequence \"" + field.path + "\": no frames found" +
                              (ec ? " (cannot list \"" + scan.string() + "\": " + ec.message() + ")" : std::string()) +
                              "; check the pattern, or give --field-frames FIRST,LAST");
    }
    const int first = *found.begin(), last = *found.rbegin();
    if (int(found.size()) != last - first + 1) {
        int gap = first;
        while (found.count(gap)) ++gap;
        throw lic::InputError("field sequence \"" + field.path + "\": frames " + std::to_string(first) + " to " +
                              std::to_string(last) + " are on disk but frame " + std::to_string(gap) +
                              " is missing; give --field-frames FIRST,LAST for a contiguous part");
    }
    for (int f = first; f <= last; ++f) {
        out.numbers.push_back(f);
        out.paths.push_back(expandFramePattern(field.path, f));
    }
    return out;
}

} // namespace vdbexport
