// VTK's messages: its output window captured, its errors turned into InputErrors.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"

#include <vtkLogger.h>
#include <vtkObjectFactory.h>
#include <vtkOutputWindow.h>

#include <cctype>
#include <mutex>
#include <sstream>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

std::string num(double v)
{
    std::ostringstream o;
    o.precision(6);
    o << v;
    return o.str();
}

namespace {

/// VTK reports problems (a truncated file, a bad tag) on its output window, not by exceptions:
/// this window keeps the text so a read can turn errors into one InputError, and keeps VTK quiet.
class CaptureWindow : public vtkOutputWindow
{
public:
    static CaptureWindow* New();
    vtkTypeMacro(CaptureWindow, vtkOutputWindow)

    void DisplayText(const char* text) override { add(mOther, text); }
    void DisplayErrorText(const char* text) override { add(mErrors, text); }
    void DisplayWarningText(const char* text) override { add(mOther, text); }
    void DisplayGenericWarningText(const char* text) override { add(mOther, text); }

    void clear()
    {
        std::lock_guard lock(mMutex);
        mErrors.clear();
        mOther.clear();
    }
    std::string errors()
    {
        std::lock_guard lock(mMutex);
        return mErrors;
    }

private:
    void add(std::string& to, const char* text)
    {
        std::lock_guard lock(mMutex);
        if (to.size() < 64 * 1024) to += text ? text : "";
    }
    std::mutex mMutex;
    std::string mErrors, mOther;
};
vtkStandardNewMacro(CaptureWindow);

CaptureWindow& captureWindow()
{
    static vtkSmartPointer<CaptureWindow> window = [] {
        auto w = vtkSmartPointer<CaptureWindow>::New();
        vtkOutputWindow::SetInstance(w);
        vtkLogger::SetStderrVerbosity(vtkLogger::VERBOSITY_OFF); // VTK's log would repeat each error on stderr
        return w;
    }();
    return *window;
}

} // namespace

void clearVtkErrors() { captureWindow().clear(); }

std::string vtkErrors() { return captureWindow().errors(); }

std::string firstError(const std::string& text)
{
    std::istringstream in(text);
    std::string line, message;
    while (std::getline(in, line)) {
        if (line.rfind("ERROR:", 0) == 0 || line.rfind("Generic Warning", 0) == 0) continue;
        const auto colon = line.find("): ");
        message = colon != std::string::npos && line.rfind("vtk", 0) == 0 ? line.substr(colon + 3) : line;
        while (!message.empty() && std::isspace(static_cast<unsigned char>(message.back()))) message.pop_back();
        if (!message.empty()) return message;
    }
    return "VTK reported an error";
}

void runChecked(vtkAlgorithm* algorithm, const std::string& path, const std::string& what,
                const std::function<void()>& update)
{
    CaptureWindow& w = captureWindow();
    w.clear();
    update();
    const std::string errors = w.errors();
    if (!errors.empty() || algorithm->GetErrorCode() != 0)
        detail::inputError(path, "cannot be read as " + what + ": " + (errors.empty() ? "read error" : firstError(errors)));
}

} // namespace vdbexport::mesh_module
