// A bake's manifest lists a SHA-256 per frame file: check each against the file on disk, recomputed,
// and that frames that differ have different digests (a manifest that repeated frame 1's digest for
// every frame, or listed stale ones, fails here).
#pragma once

#include "vdbexport/io/Sha256.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>
#include <fstream>
#include <set>
#include <string>

namespace lictest {

/// Every file of the manifest at `manifestPath` has its recomputed digest there; `frames` files.
inline void expectManifestDigests(const std::filesystem::path& manifestPath, std::size_t frames)
{
    std::ifstream in(manifestPath);
    ASSERT_TRUE(in) << "no manifest " << manifestPath;
    const nlohmann::json m = nlohmann::json::parse(in);
    ASSERT_EQ(m["files"].size(), frames) << manifestPath;
    ASSERT_EQ(m["sha256"].size(), frames) << manifestPath;
    std::set<std::string> distinct;
    for (const auto& f : m["files"]) {
        const std::string name = f.get<std::string>();
        const std::filesystem::path file = manifestPath.parent_path() / name;
        ASSERT_TRUE(m["sha256"].contains(name)) << manifestPath << ": no digest for " << name;
        EXPECT_EQ(m["sha256"][name].get<std::string>(), vdbexport::sha256OfFile(file.string()))
            << manifestPath << ": the digest of " << name << " is not the file's";
        distinct.insert(m["sha256"][name].get<std::string>());
    }
    EXPECT_EQ(distinct.size(), frames) << manifestPath << ": frames share a digest";
}

} // namespace lictest
