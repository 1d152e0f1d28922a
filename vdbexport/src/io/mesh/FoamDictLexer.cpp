// The lexer of the OpenFOAM dictionary expander (FoamDictImpl.h), close to OpenFOAM's ISstream:
// words with OpenFOAM's parentheses rule, strings, punctuation, $variables, #directives, #{ … #}
// verbatim blocks, comments skipped; a list of only numbers and words (a nonuniform field) is one
// token kept as written, so that large fields pass through without being taken apart.
#include "io/mesh/FoamDictImpl.h"

#include <algorithm>
#include <cctype>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module::foam_dict {

namespace {

/// OpenFOAM's word::valid.
bool wordChar(char c)
{
    return !isSpace(c) && c != '"' && c != '\'' && c != '/' && c != ';' && c != '{' && c != '}';
}

} // namespace

std::string where(const Source* src, int line)
{
    std::string f = src && !src->file.empty() ? src->file.string() : std::string("<dictionary>");
    return f + ":" + std::to_string(line);
}

std::string where(const Token& t) { return where(t.src, t.line); }

std::string unquote(const std::string& s)
{
    return s.size() >= 2 && s.front() == '"' && s.back() == '"' ? s.substr(1, s.size() - 2) : s;
}

std::string dq(const std::string& s) { return "\"" + s + "\""; }

Token Lexer::next()
{
    if (peeked_) {
        Token t = std::move(*peeked_);
        peeked_.reset();
        return t;
    }
    return lex();
}

const Token& Lexer::peek()
{
    if (!peeked_) peeked_ = lex();
    return *peeked_;
}

void Lexer::skipLine()
{
    peeked_.reset(); // a token looked at is part of the line
    int depth = 0;
    while (p_ < s_.size()) {
        const char c = s_[p_];
        if (c == '\n' && depth <= 0) return;
        if (c == '\n') ++line_;
        if (c == '(') ++depth;
        if (c == ')') --depth;
        ++p_;
    }
}

void Lexer::error(int line, const std::string& what) const { fail(where(&src_, line) + ": " + what); }

char Lexer::skipBlanks()
{
    char sep = 0;
    while (p_ < s_.size()) {
        const char c = s_[p_];
        if (isSpace(c)) {
            if (c == '\n') {
                ++line_;
                sep = '\n';
            } else if (!sep) {
                sep = ' ';
            }
            ++p_;
        } else if (c == '/' && at(p_ + 1) == '/') {
            while (p_ < s_.size() && s_[p_] != '\n') ++p_;
            if (!sep) sep = ' ';
        } else if (c == '/' && at(p_ + 1) == '*') {
            const int start = line_;
            const std::size_t end = s_.find("*/", p_ + 2);
            if (end == std::string::npos) error(start, "unterminated /* comment");
            line_ += int(std::count(s_.begin() + std::ptrdiff_t(p_), s_.begin() + std::ptrdiff_t(end), '\n'));
            p_ = end + 2;
            if (!sep) sep = ' ';
        } else {
            break;
        }
    }
    return sep;
}

Token Lexer::make(Tok kind, std::size_t begin, char sep, int line)
{
    Token t;
    t.kind = kind;
    t.text.assign(s_, begin, p_ - begin);
    t.sep = sep;
    t.src = &src_;
    t.line = line;
    line_ += int(std::count(t.text.begin(), t.text.end(), '\n'));
    return t;
}

bool Lexer::rawList()
{
    if (p_ < noRawUntil_) return false;
    int depth = 0;
    for (std::size_t i = p_; i < s_.size(); ++i) {
        const char c = s_[i];
        if (c == '(') {
            ++depth;
        } else if (c == ')') {
            if (--depth == 0) {
                rawEnd_ = i + 1;
                return true;
            }
        } else if (c == '"' || c == '\'' || c == '#' || c == '$' || c == '/' || c == '{' || c == '}' ||
                   c == ';') {
            noRawUntil_ = i;
            return false;
        }
    }
    noRawUntil_ = s_.size();
    return false;
}

Token Lexer::lexString(char sep, int line)
{
    const std::size_t begin = p_++;
    while (p_ < s_.size() && s_[p_] != '"') p_ += s_[p_] == '\\' ? 2 : 1;
    if (p_ >= s_.size()) error(line, "unterminated string");
    ++p_;
    return make(Tok::String, begin, sep, line);
}

void Lexer::wordChars(bool allowSlash)
{
    int depth = 0;
    while (p_ < s_.size()) {
        const char c = s_[p_];
        if (!(wordChar(c) || (allowSlash && c == '/'))) break;
        if (c == '(') ++depth;
        if (c == ')' && depth-- == 0) break;
        ++p_;
    }
}

Token Lexer::lexHash(std::size_t begin, char sep, int line)
{
    if (at(p_ + 1) == '{') { // #{ verbatim #}
        const std::size_t end = s_.find("#}", p_ + 2);
        if (end == std::string::npos) error(line, "unterminated #{ … #} block");
        p_ = end + 2;
        return make(Tok::Verbatim, begin, sep, line);
    }
    ++p_;
    while (p_ < s_.size() && (std::isalnum(static_cast<unsigned char>(s_[p_])) || s_[p_] == '_')) ++p_;
    return make(Tok::Directive, begin, sep, line);
}

Token Lexer::lexDollar(std::size_t begin, char sep, int line)
{
    ++p_;
    if (at(p_) == '{') {
        int depth = 0;
        while (p_ < s_.size()) {
            const char c = s_[p_++];
            if (c == '{') ++depth;
            if (c == '}' && --depth == 0) break;
        }
        if (depth != 0) error(line, "unterminated ${…}");
    } else {
        wordChars(true);
    }
    return make(Tok::Variable, begin, sep, line);
}

Token Lexer::lex()
{
    const char sep = skipBlanks();
    const int line = line_;
    const std::size_t begin = p_;
    if (p_ >= s_.size()) {
        Token t;
        t.sep = sep;
        t.src = &src_;
        t.line = line;
        return t;
    }
    const char c = s_[p_];
    if (c == '"') return lexString(sep, line);
    if (c == '#') return lexHash(begin, sep, line);
    if (c == '$') return lexDollar(begin, sep, line);
    if (c == '(' && rawList()) {
        p_ = rawEnd_;
        return make(Tok::Raw, begin, sep, line);
    }
    if (c == ';' || c == '{' || c == '}' || c == '(' || c == ')' || c == '[' || c == ']' || c == ',' ||
        c == '/' || c == '\'') {
        ++p_;
        return make(Tok::Punct, begin, sep, line);
    }
    if (std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '.' || c == '+') {
        while (p_ < s_.size() && wordChar(s_[p_]) && s_[p_] != '(' && s_[p_] != ')' && s_[p_] != '[' &&
               s_[p_] != ']' && s_[p_] != ',')
            ++p_;
    } else {
        wordChars(false);
    }
    if (p_ == begin) ++p_; // cannot happen for valid input; never loop
    return make(Tok::Word, begin, sep, line);
}

/// The words of a list token sequence (`2(wall foo)`, `List<word> 1(wall)`, a raw list): names only.
std::vector<std::string> listWords(const std::vector<Token>& tokens)
{
    std::vector<std::string> words;
    bool inList = false;
    for (const Token& t : tokens) {
        if (t.kind == Tok::Raw) {
            Source s{t.src ? t.src->file : fs::path(), t.text.substr(1, t.text.size() - 2)};
            Lexer lx(s);
            for (Token u = lx.next(); u.kind != Tok::End; u = lx.next())
                if (u.kind == Tok::Word) words.push_back(u.text);
            continue;
        }
        if (t.is('(')) inList = true;
        if (t.is(')')) inList = false;
        if (inList && (t.kind == Tok::Word || t.kind == Tok::String))
            words.push_back(t.kind == Tok::String ? t.text.substr(1, t.text.size() - 2) : t.text);
    }
    return words;
}

} // namespace vdbexport::mesh_module::foam_dict
