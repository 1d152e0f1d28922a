// The OpenFOAM dictionary expander's parts (FoamDict.h), shared by its files only: the lexer
// (FoamDictLexer.cpp), the dictionary tree and the parser that builds it entry by entry
// (FoamDictParse.cpp), $variables with OpenFOAM's scoped search (FoamDictVars.cpp), #include and
// its kin (FoamDictIncludes.cpp), and boundaryField per patch with the boundary file it needs
// (FoamDictBoundary.cpp). FoamDict.cpp has the entry points and writes the tree back as text.
// Plain C++ (no VTK), as FoamDict.h.
#pragma once

#include "io/mesh/FoamDict.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cstddef>
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <regex>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

namespace vdbexport::mesh_module::foam_dict {

inline constexpr int kMaxDictDepth = 64;

[[noreturn]] inline void fail(const std::string& msg) { throw lic::InputError(msg); }

inline bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\f' || c == '\v'; }

/// Binary data in the text (a `format binary` field's lists: raw doubles always hold control bytes).
/// A `format binary` header over text only (hand-written tutorial fields have it) is text.
/// (FoamDict.cpp)
bool isBinary(std::string_view text);

// ---- lexer (FoamDictLexer.cpp) ----------------------------------------------------------------

struct Source
{
    std::filesystem::path file;
    std::string text;
};

enum class Tok { End, Word, String, Punct, Variable, Directive, Verbatim, Raw };

struct Token
{
    Tok kind = Tok::End;
    std::string text; // as written (strings with their quotes, variables with their '$')
    char sep = ' ';   // what stood before it: 0 nothing, ' ' blanks or a comment, '\n' a line break
    const Source* src = nullptr;
    int line = 0;
    bool is(char c) const { return kind == Tok::Punct && text.size() == 1 && text[0] == c; }
};

/// "file:line" for messages ("<dictionary>:line" for a text without a file).
std::string where(const Source* src, int line);
std::string where(const Token& t);

/// A string token's text without its quotes (anything else as it is).
std::string unquote(const std::string& s);
/// `s` in double quotes: a "regex" key as written, a name in a message.
std::string dq(const std::string& s);

/// Tokens as OpenFOAM's ISstream reads them; a list of numbers and words is one Raw token.
class Lexer
{
public:
    explicit Lexer(const Source& src) : src_(src), s_(src.text) {}

    const Source& source() const { return src_; }

    Token next();
    const Token& peek();

    /// Drop the rest of the current line (parentheses balanced across lines): #includeFunc's arguments.
    void skipLine();

private:
    char at(std::size_t i) const { return i < s_.size() ? s_[i] : '\0'; }

    [[noreturn]] void error(int line, const std::string& what) const;
    /// Blanks and comments; the separator they make.
    char skipBlanks();
    Token make(Tok kind, std::size_t begin, char sep, int line);
    /// A list that holds only numbers and words, e.g. a nonuniform field: one token, kept as written.
    bool rawList();
    Token lexString(char sep, int line);
    /// Word characters, with OpenFOAM's parentheses rule (`div(phi,U)` is one word).
    void wordChars(bool allowSlash);
    Token lexHash(std::size_t begin, char sep, int line);
    Token lexDollar(std::size_t begin, char sep, int line);
    Token lex();

    const Source& src_;
    const std::string& s_;
    std::size_t p_ = 0;
    int line_ = 1;
    std::size_t noRawUntil_ = 0, rawEnd_ = 0;
    std::optional<Token> peeked_;
};

/// The words of a list token sequence (`2(wall foo)`, `List<word> 1(wall)`, a raw list): names only.
std::vector<std::string> listWords(const std::vector<Token>& tokens);

// ---- dictionary tree (FoamDictParse.cpp) ------------------------------------------------------

struct Dict;

struct Entry
{
    std::string key;      // a string key without its quotes
    bool pattern = false; // a quoted key: a regular expression
    std::vector<Token> value;
    std::unique_ptr<Dict> dict; // set: a dictionary entry
    const Source* src = nullptr;
    int line = 0;
    mutable std::optional<std::regex> re;
    mutable bool badRe = false;

    bool matches(const std::string& name) const;
};

struct Dict
{
    Dict* parent = nullptr;
    std::vector<std::unique_ptr<Entry>> entries;
    std::unordered_map<std::string, Entry*> literal;

    const Entry* findLocal(const std::string& key, bool patterns) const
    {
        if (auto it = literal.find(key); it != literal.end()) return it->second;
        if (patterns)
            for (auto it = entries.rbegin(); it != entries.rend(); ++it)
                if ((*it)->pattern && (*it)->matches(key)) return it->get();
        return nullptr;
    }

    Entry* findLiteral(const std::string& key)
    {
        auto it = literal.find(key);
        return it == literal.end() ? nullptr : it->second;
    }

    void remove(const Entry* e)
    {
        literal.erase(e->key);
        entries.erase(std::remove_if(entries.begin(), entries.end(), [&](const auto& p) { return p.get() == e; }),
                      entries.end());
    }

    void reparent()
    {
        for (auto& e : entries)
            if (e->dict) e->dict->parent = this;
    }
};

std::unique_ptr<Entry> cloneEntry(const Entry& e, Dict* parent, int depth);
std::unique_ptr<Dict> cloneDict(const Dict& d, Dict* parent, int depth);

enum class Mode { Merge, Overwrite, Default };

/// Add `e` to `d` as OpenFOAM's dictionary::add(entry, mergeEntry) does: a dictionary merges into
/// a dictionary of the same key, anything else replaces the old entry where it stood.
void addEntry(Dict& d, std::unique_ptr<Entry> e, Mode mode, int depth);

// ---- includes (FoamDictIncludes.cpp) ----------------------------------------------------------

/// #include, #sinclude, #includeIfPresent, #includeEtc, #sincludeEtc.
bool isInclude(const std::string& directive);

/// The file's text; nullopt for what is not a readable regular file of at most 1 GiB (and for
/// anything under /proc, /sys, /dev).
std::optional<std::string> readWholeFile(const std::filesystem::path& path);

// ---- expansion --------------------------------------------------------------------------------

/// One expansion: the texts read (the dictionary, its included files) and the tree built from them.
/// Its parts are defined by concept: parsing in FoamDictParse.cpp, variables in FoamDictVars.cpp,
/// includes in FoamDictIncludes.cpp, boundaryField in FoamDictBoundary.cpp.
class Expander
{
public:
    Expander(const FoamDictContext& ctx, std::size_t inputBytes);

    const Source& addSource(std::filesystem::path file, std::string text);

    /// Entries up to the end of `lx` (a file) or the '}' that closes a sub-dictionary.
    void parseEntries(Dict& d, Lexer& lx, int dictDepth, int fileDepth, bool subDict, bool includedFile);

    /// A primitive entry's value: tokens up to ';' with variables and #include expanded (an
    /// included file's tokens up to its first ';', as OpenFOAM's primitiveEntry reads them).
    void readValue(const Dict& scope, Lexer& lx, std::vector<Token>& out, int fileDepth);

    void rewriteBoundary(Dict& root);

private:
    /// Count what an expansion holds (a token: its text and its own size) against the budget.
    void charge(std::size_t n)
    {
        bytes_ += n + sizeof(Token);
        if (bytes_ > budget_)
            fail("the dictionary expands to more than " + std::to_string(budget_ >> 20) + " MiB: a $variable loop?");
    }

    void expandVariable(const Dict& scope, const Token& var, std::vector<Token>& out);
    void appendDictTokens(const Dict& d, const Token& at, std::vector<Token>& out, int depth);
    std::string expandString(const Dict& scope, const std::string& s, const Token& at);
    std::filesystem::path resolveInclude(const Dict& scope, const Token& directive, const Token& arg);
    std::optional<std::filesystem::path> findEtc(const std::string& name) const;
    /// The file of an #include-like directive (its argument read from lx); nullopt: optional and absent.
    std::optional<const Source*> includeSource(const Dict& scope, Lexer& lx, const Token& directive, int fileDepth);
    bool directiveAtKeyword(Dict& d, Lexer& lx, const Token& t, int dictDepth, int fileDepth, Mode& mode);
    void mergeVariable(Dict& d, const Token& t, int dictDepth);
    void removeEntries(Dict& d, Lexer& lx);

    const FoamDictContext& ctx_;
    std::filesystem::path caseDir_;
    std::deque<Source> sources_;
    std::size_t bytes_ = 0, budget_;
};

} // namespace vdbexport::mesh_module::foam_dict
