// The checked-file cache (checkedVdb: each unchanged file checked once per process) and the read
// licvdb-readcheck runs (readCheckMain), both of ReadCheck.h.
#include "vdbexport/io/ReadCheck.h"

#include "vdbexport/io/VdbReader.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <iostream>
#include <map>
#include <mutex>
#include <new>
#include <tuple>

#include <sys/stat.h>

namespace vdbexport::detail {

namespace {

/// Files that passed checkedVdb, keyed by what identifies an unchanged file.
struct FileKey
{
    dev_t dev;
    ino_t ino;
    off_t size;
    int64_t mtimeNs;
    bool operator<(const FileKey& o) const
    {
        return std::tie(dev, ino, size, mtimeNs) < std::tie(o.dev, o.ino, o.size, o.mtimeNs);
    }
};

std::mutex sCheckedMutex;
std::map<FileKey, VdbCheckResult> sChecked;

bool fileKey(const std::string& path, FileKey& key)
{
    struct stat st{};
    if (::stat(path.c_str(), &st) != 0) return false;
    key = {st.st_dev, st.st_ino, st.st_size, int64_t(st.st_mtim.tv_sec) * 1000000000 + st.st_mtim.tv_nsec};
    return true;
}

} // namespace

VdbCheckResult checkedVdb(const std::string& path)
{
    FileKey before{};
    const bool known = fileKey(path, before);
    if (known) {
        const std::lock_guard<std::mutex> lock(sCheckedMutex);
        if (const auto it = sChecked.find(before); it != sChecked.end()) return it->second;
    }
    // The child (which runs layer 1 itself before reading) works beside this process's layer 1;
    // if layer 1 refuses the file here, the child is stopped and that message is the one given.
    IsolatedCheck child = startIsolatedCheck(path);
    VdbCheckResult result = checkVdbStructure(path);
    child.finish();
    FileKey after{};
    if (known && fileKey(path, after) && !(before < after) && !(after < before)) {
        const std::lock_guard<std::mutex> lock(sCheckedMutex);
        sChecked[after] = result;
    }
    return result;
}

void clearCheckedVdbCache()
{
    const std::lock_guard<std::mutex> lock(sCheckedMutex);
    sChecked.clear();
}

int readCheckMain(const std::string& path, const char* who)
{
    try {
        openvdb::initialize();
        // VdbReader runs layer 1 first (checkedVdb), then what licvdb's reads do with the file.
        // (`licvdb info` describes grids already read: nothing of the file's is left to check.)
        VdbReader reader(path);
        (void)reader.fileMetadata();
        (void)reader.gridTypes();
        (void)reader.readAllGrids();
        return 0;
    } catch (const lic::InputError& e) {
        std::cerr << who << ": error: " << e.what() << "\n";
        return 2;
    } catch (const std::bad_alloc&) {
        std::cerr << who << ": error: out of memory\n";
        return 1;
    } catch (const std::exception& e) {
        std::cerr << who << ": error: " << e.what() << "\n";
        return 1;
    }
}

} // namespace vdbexport::detail
