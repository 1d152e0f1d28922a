// VdbReader (VdbReader.h): a checked .vdb file opened by OpenVDB, every failure a lic::InputError
// naming the file; and OpenVDB's logger kept quiet while it opens a file of a newer format.
#include "vdbexport/io/VdbReader.h"

#include "vdbexport/io/ReadCheck.h"
#include "Quote.h"
#include "VdbGridReader.h"

#include <lic/util/Error.h>

#include <log4cplus/logger.h>

#include <algorithm>
#include <cctype>
#include <exception>
#include <mutex>

namespace vdbexport::detail {

namespace {

/// An exception message fit to quote: control characters and runs of blanks collapsed (OpenVDB
/// echoes garbage read from damaged files), at most 200 characters.
std::string cleanMessage(const char* what)
{
    std::string out;
    for (const char* c = what; *c && out.size() < 200; ++c) {
        const bool blank = std::isspace(static_cast<unsigned char>(*c)) || std::iscntrl(static_cast<unsigned char>(*c));
        if (blank && (out.empty() || out.back() == ' ')) continue;
        out.push_back(blank ? ' ' : *c);
    }
    if (out.size() >= 200) out += "...";
    return out;
}

/// Run `fn`, turning any exception other than lic::Error into a lic::InputError that names
/// the file and what was being done (OpenVDB reports corrupt and truncated files as IoError,
/// RuntimeError, KeyError, … and sometimes as std::exception).
template<typename Fn>
auto guardRead(const std::string& path, const char* what, Fn&& fn) -> decltype(fn())
{
    try {
        return fn();
    } catch (const lic::Error&) {
        throw;
    } catch (const std::exception& e) { // openvdb::Exception is a std::exception
        throw lic::InputError("cannot read " + q(path) + " (" + what + "): " + cleanMessage(e.what())
                              + "; expected an intact OpenVDB .vdb file (corrupt or truncated?)");
    }
}

} // namespace

VdbReader::VdbReader(std::string path) : mPath(std::move(path))
{
    openvdb::initialize();
    try {
        // The path itself (none, missing, a directory, empty, unreadable) first: the check's
        // rules no-path, not-found, directory, empty and open, with their marker.
        mCheck = checkedVdb(mPath);
    } catch (const lic::Error&) {
        throw;
    } catch (const std::exception& e) {
        throw lic::InputError("cannot read " + q(mPath) + ": " + cleanMessage(e.what()));
    }
    mFile = std::make_unique<openvdb::io::File>(mPath);
    try {
        const QuietNewerFormat quiet(mCheck.fileVersion);
        mFile->open(/*delayLoad=*/false);
        // Grids are read through a stream that costs fewer system calls (VdbGridReader.h); files
        // without grid offsets only io::File reads.
        mGrids = std::make_unique<GridFileReader>(mPath);
        if (!mGrids->random()) mGrids.reset();
    } catch (const std::exception& e) {
        const std::string msg = cleanMessage(e.what());
        if (msg.find("not a VDB file") != std::string::npos)
            throw lic::InputError(q(mPath) + " is not an OpenVDB file (no VDB header); "
                                  "expected a .vdb file");
        throw lic::InputError("cannot open " + q(mPath) + " as a .vdb file: " + msg
                              + "; expected an intact OpenVDB .vdb file (corrupt or truncated?)");
    }
}

VdbReader::~VdbReader()
{
    try {
        if (mFile && mFile->isOpen()) mFile->close();
    } catch (...) {
    }
}

std::vector<std::pair<std::string, std::string>> VdbReader::gridTypes()
{
    return guardRead(mPath, "reading grid headers", [&] {
        std::vector<std::pair<std::string, std::string>> out;
        const auto grids = mFile->readAllGridMetadata();
        for (const auto& g : *grids) out.emplace_back(g->getName(), g->valueType());
        return out;
    });
}

openvdb::GridBase::Ptr VdbReader::readGrid(const std::string& name)
{
    const std::string what = "reading grid " + q(name);
    return guardRead(mPath, what.c_str(), [&] {
        for (const auto& g : mCheck.grids)
            if (g.name == name && !g.skipReason.empty())
                throw lic::InputError("grid " + q(name) + " in " + q(mPath) + " (" + g.gridType
                                      + ") cannot be read: " + g.skipReason);
        if (!mFile->hasGrid(name))
            throw lic::InputError("grid " + q(name) + " not found in " + q(mPath)
                                  + "; the file has: " + listGrids(gridTypes()));
        auto grid = mGrids ? mGrids->readGrid(name) : mFile->readGrid(name);
        if (!grid) throw lic::InputError("grid " + q(name) + " in " + q(mPath) + " could not be read");
        return grid;
    });
}

openvdb::GridPtrVec VdbReader::readAllGrids()
{
    return guardRead(mPath, "reading grids", [&] {
        const bool skipped = std::any_of(mCheck.grids.begin(), mCheck.grids.end(),
                                         [](const VdbGridCheck& g) { return !g.skipReason.empty(); });
        if (!skipped && mGrids) return mGrids->readAllGrids();
        if (!skipped) {
            const auto grids = mFile->getGrids();
            return grids ? *grids : openvdb::GridPtrVec{};
        }
        openvdb::GridPtrVec grids; // grids of types licvdb does not read are left out
        for (const auto& g : mCheck.grids)
            if (g.skipReason.empty()) grids.push_back(mGrids ? mGrids->readGrid(g.name) : mFile->readGrid(g.name));
        return grids;
    });
}

openvdb::MetaMap::Ptr VdbReader::fileMetadata()
{
    return guardRead(mPath, "reading file metadata", [&] {
        auto meta = mFile->getMetadata();
        return meta ? meta : std::make_shared<openvdb::MetaMap>();
    });
}

namespace {
std::mutex sQuietMutex;
int sQuietScopes = 0;
log4cplus::LogLevel sQuietSaved = log4cplus::NOT_SET_LOG_LEVEL;
/// OpenVDB's logger (openvdb/util/logging.h getLogger(): its headers use it only where the
/// program defines OPENVDB_USE_LOG4CPLUS, so licvdb names it itself).
log4cplus::Logger openvdbLogger() { return log4cplus::Logger::getInstance(LOG4CPLUS_TEXT("openvdb")); }
} // namespace

QuietNewerFormat::QuietNewerFormat(uint32_t fileVersion) : mActive(fileVersion > openvdb::OPENVDB_FILE_VERSION)
{
    if (!mActive) return;
    const std::lock_guard<std::mutex> lock(sQuietMutex);
    if (sQuietScopes++ == 0) {
        log4cplus::Logger logger = openvdbLogger();
        sQuietSaved = logger.getLogLevel();
        logger.setLogLevel(std::max(sQuietSaved, log4cplus::ERROR_LOG_LEVEL));
    }
}

QuietNewerFormat::~QuietNewerFormat()
{
    if (!mActive) return;
    const std::lock_guard<std::mutex> lock(sQuietMutex);
    if (--sQuietScopes == 0) openvdbLogger().setLogLevel(sQuietSaved);
}

std::string listGrids(const std::vector<std::pair<std::string, std::string>>& grids)
{
    if (grids.empty()) return "no grids";
    std::string s;
    for (const auto& [name, type] : grids) {
        if (!s.empty()) s += ", ";
        s += (name.empty() ? std::string("(unnamed)") : name) + " (" + type + ")";
    }
    return s;
}

} // namespace vdbexport::detail
