#include "dataset/h5_guard.h"

#include "dataset/error.h"

#include <fcntl.h>
#include <hdf5.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <set>
#include <vector>

namespace layersnet::dataset::h5 {
namespace {

// Set in the child: the reader it runs opens the same file again, unguarded.
bool g_in_child = false;

// Datasets beyond this are refused by the readers' size checks before any read.
constexpr uint64_t kMaxProbeBytes = uint64_t{1} << 30;

// Reads `n` elements of `ftype` through `read` into memory of the native type, then frees
// whatever libhdf5 allocated for variable-length members.
template <class Read>
void read_through(hid_t ftype, hid_t space, Read read) {
  const hssize_t n = H5Sget_simple_extent_npoints(space);
  if (n <= 0) return;
  hid_t mtype = -1;
  if (H5Tis_variable_str(ftype) > 0) {
    // The file's character set: with another one there is no conversion path, the read fails
    // at once and never reaches the global heap a real read goes through.
    mtype = H5Tcopy(H5T_C_S1);
    H5Tset_size(mtype, H5T_VARIABLE);
    H5Tset_cset(mtype, H5Tget_cset(ftype) == H5T_CSET_UTF8 ? H5T_CSET_UTF8 : H5T_CSET_ASCII);
  } else {
    mtype = H5Tget_native_type(ftype, H5T_DIR_DEFAULT);
  }
  if (mtype < 0) return;
  const size_t size = H5Tget_size(mtype);
  if (size > 0 && static_cast<uint64_t>(n) * size <= kMaxProbeBytes) {
    std::vector<unsigned char> buf(static_cast<size_t>(n) * size);
    if (read(mtype, buf.data()) >= 0 && (H5Tdetect_class(mtype, H5T_VLEN) > 0 || H5Tis_variable_str(mtype) > 0))
      H5Dvlen_reclaim(mtype, space, H5P_DEFAULT, buf.data());
  }
  H5Tclose(mtype);
}

herr_t read_attribute(hid_t loc, const char* name, const H5A_info_t*, void*) {
  const hid_t a = H5Aopen(loc, name, H5P_DEFAULT);
  if (a < 0) return 0;
  const hid_t type = H5Aget_type(a), space = H5Aget_space(a);
  if (type >= 0 && space >= 0) read_through(type, space, [&](hid_t m, void* buf) { return H5Aread(a, m, buf); });
  if (type >= 0) H5Tclose(type);
  if (space >= 0) H5Sclose(space);
  H5Aclose(a);
  return 0;
}

herr_t read_object(hid_t parent, const char* name, const H5O_info_t* info, void*) {
  const hid_t o = H5Oopen(parent, name, H5P_DEFAULT);
  if (o < 0) return 0;
  H5Aiterate2(o, H5_INDEX_NAME, H5_ITER_NATIVE, nullptr, read_attribute, nullptr);
  if (info->type == H5O_TYPE_DATASET) {
    const hid_t type = H5Dget_type(o), space = H5Dget_space(o);
    if (type >= 0 && space >= 0)
      read_through(type, space, [&](hid_t m, void* buf) { return H5Dread(o, m, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf); });
    if (type >= 0) H5Tclose(type);
    if (space >= 0) H5Sclose(space);
  }
  H5Oclose(o);
  return 0;
}

// Runs in the child: everything libhdf5 can be asked to read from the file.
void read_everything(hid_t file) {
  if (file < 0) return;
  H5Ovisit2(file, H5_INDEX_NAME, H5_ITER_NATIVE, read_object, nullptr, H5O_INFO_BASIC);
  H5Fclose(file);
}

std::string signal_name(int sig) {
  const char* d = sigdescr_np(sig);
  return std::string(d ? d : "signal") + " (signal " + std::to_string(sig) + ")";
}

int guard_seconds() {
  const char* v = std::getenv("LAYERSNET_HDF5_GUARD_SECONDS");
  const int s = v ? std::atoi(v) : 0;
  return s > 0 ? s : kGuardSeconds;
}

template <class Probe>
void run_guarded(const std::string& name, Probe probe) {
  std::fflush(nullptr);  // the child must not flush the parent's buffered output again
  const pid_t pid = ::fork();
  if (pid < 0) return;  // no child to spare: read unguarded, as before
  if (pid == 0) {
    // Silent, default-signal child: a crash ends it by the signal, which the parent reports.
    const int devnull = ::open("/dev/null", O_WRONLY);
    if (devnull >= 0) {
      ::dup2(devnull, STDOUT_FILENO);
      ::dup2(devnull, STDERR_FILENO);
    }
    for (int sig : {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT}) ::signal(sig, SIG_DFL);
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    g_in_child = true;
    try {
      probe();
    } catch (...) {  // an error libhdf5 reports: the parent's own read reports it with context
    }
    ::_exit(0);  // never atexit: libhdf5's shutdown would flush the parent's open files
  }
  const int seconds = guard_seconds();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  int status = 0;
  for (;;) {
    const pid_t done = ::waitpid(pid, &status, WNOHANG);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) return;
    if (std::chrono::steady_clock::now() > deadline) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      throw DatasetError(name, "/",
                         "reading this file did not finish within " + std::to_string(seconds) +
                             " s (libhdf5 loops forever on some corrupt files); the file is corrupt: regenerate it or "
                             "restore it from a copy");
    }
    ::usleep(1000);
  }
  if (WIFSIGNALED(status))
    throw DatasetError(name, "/",
                       "libhdf5 crashed reading this file (" + signal_name(WTERMSIG(status)) +
                           "); the file is corrupt: regenerate it or restore it from a copy");
  if (WIFEXITED(status) && WEXITSTATUS(status) != 0)
    throw DatasetError(name, "/",
                       "libhdf5 failed reading this file (exit " + std::to_string(WEXITSTATUS(status)) +
                           "); the file is corrupt: regenerate it or restore it from a copy");
}

bool trusted() {
  if (g_in_child) return true;
  const char* v = std::getenv("LAYERSNET_TRUST_HDF5");
  return v && std::strcmp(v, "1") == 0;
}

}  // namespace

void guard_file(const std::string& path, const std::function<void()>& read) {
  if (trusted()) return;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return;  // the opener reports it
  static std::mutex mutex;
  static std::set<std::string> checked;
  const std::string key = path + '\n' + std::to_string(st.st_size) + '\n' + std::to_string(st.st_mtim.tv_sec) + '.' +
                          std::to_string(st.st_mtim.tv_nsec);
  std::lock_guard<std::mutex> lock(mutex);
  if (checked.count(key)) return;
  run_guarded(path, [&] {
    if (read)
      read();
    else if (H5Fis_hdf5(path.c_str()) > 0)
      read_everything(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT));
  });
  checked.insert(key);
}

void guard_image(std::span<const uint8_t> bytes, const std::string& name, const std::function<void()>& read) {
  if (trusted() || bytes.empty()) return;
  run_guarded(name, [&] {
    if (read) {
      read();
      return;
    }
    const hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
    H5Pset_fapl_core(fapl, 1 << 16, 0);
    if (H5Pset_file_image(fapl, const_cast<uint8_t*>(bytes.data()), bytes.size()) >= 0)
      read_everything(H5Fopen(name.c_str(), H5F_ACC_RDONLY, fapl));
  });
}

}  // namespace layersnet::dataset::h5
