#pragma once
/// Runs a program as a user would, for the command-line tests: its exit code or the signal that
/// ended it, stdout and stderr apart, optionally in another working directory, with extra
/// environment variables, a memory limit, a CPU-time limit (which another process on the core does
/// not bring closer, unlike the wall clock), and a wall-clock limit after which the whole process
/// group is killed (a stalled command fails its test instead of hanging the suite).

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

extern char** environ;

namespace test {

struct Outcome {
    int code = -1;             // exit code; -1 when a signal ended the process (or it was killed)
    int signal = 0;            // the signal that ended it, 0 when it exited
    bool timed_out = false;    // killed after RunOptions::timeout_seconds
    bool cpu_limited = false;  // ended by the kernel past RunOptions::cpu_seconds
    double seconds = 0;        // wall-clock time
    double cpu_seconds = 0;    // the process's CPU time, user and system
    std::string out;           // stdout
    std::string err;           // stderr
};

struct RunOptions {
    std::string cwd;                  // working directory; empty: the caller's
    double timeout_seconds = 0;       // 0: wait for ever
    double cpu_seconds = 0;           // RLIMIT_CPU (whole seconds, rounded up): SIGXCPU past it; 0: none
    std::uint64_t address_space = 0;  // RLIMIT_AS in bytes; 0: unlimited (sanitizers need it so)
    std::vector<std::string> env;     // "NAME=value" added to (or replacing in) the environment
};

/// The argument as the shell would need it written.
inline std::string shell_quote(const std::string& s) {
    if (!s.empty() && s.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_./=:,+@%") ==
                          std::string::npos)
        return s;
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
}

/// Runs argv[0] (a path, not searched in PATH) with the arguments argv[1..]; stdin is /dev/null.
inline Outcome run_process(const std::vector<std::string>& argv, const RunOptions& o = {}) {
    Outcome r;
    // Everything the child needs is built before fork(): after it only async-signal-safe calls.
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    std::vector<std::string> env_text;
    for (char** e = environ; *e; ++e) {
        const std::string entry = *e;
        bool replaced = false;
        for (const std::string& add : o.env)
            if (entry.substr(0, entry.find('=') + 1) == add.substr(0, add.find('=') + 1)) replaced = true;
        if (!replaced) env_text.push_back(entry);
    }
    env_text.insert(env_text.end(), o.env.begin(), o.env.end());
    std::vector<char*> envp;
    for (const std::string& e : env_text) envp.push_back(const_cast<char*>(e.c_str()));
    envp.push_back(nullptr);

    int out_pipe[2], err_pipe[2];
    if (::pipe2(out_pipe, O_CLOEXEC) != 0 || ::pipe2(err_pipe, O_CLOEXEC) != 0) {
        r.err = std::string("pipe: ") + std::strerror(errno);
        return r;
    }
    const auto start = std::chrono::steady_clock::now();
    const pid_t pid = ::fork();
    if (pid == 0) {
        ::setpgid(0, 0);
        const int in = ::open("/dev/null", O_RDONLY);
        if (in < 0 || ::dup2(in, 0) < 0 || ::dup2(out_pipe[1], 1) < 0 || ::dup2(err_pipe[1], 2) < 0) ::_exit(127);
        if (!o.cwd.empty() && ::chdir(o.cwd.c_str()) != 0) ::_exit(127);
        if (o.address_space) {
            const rlimit lim{o.address_space, o.address_space};
            ::setrlimit(RLIMIT_AS, &lim);
        }
        if (o.cpu_seconds > 0) {  // the soft limit sends SIGXCPU, the hard one (a second on) SIGKILL
            const rlim_t soft = rlim_t(o.cpu_seconds) + (o.cpu_seconds > double(rlim_t(o.cpu_seconds)) ? 1 : 0);
            const rlimit lim{soft, soft + 1};
            ::setrlimit(RLIMIT_CPU, &lim);
        }
        ::execve(args[0], args.data(), envp.data());
        ::_exit(127);
    }
    ::close(out_pipe[1]);
    ::close(err_pipe[1]);
    if (pid < 0) {
        ::close(out_pipe[0]);
        ::close(err_pipe[0]);
        r.err = std::string("fork: ") + std::strerror(errno);
        return r;
    }
    ::setpgid(pid, pid);  // also in the parent: whichever runs first, the group exists before a kill
    const auto deadline = start + std::chrono::duration<double>(o.timeout_seconds);
    pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
    std::string* sinks[2] = {&r.out, &r.err};
    int open_fds = 2;
    char buf[65536];
    while (open_fds > 0) {
        int wait_ms = -1;
        if (o.timeout_seconds > 0) {
            const auto left =
                std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
            if (left.count() <= 0) {
                r.timed_out = true;
                ::kill(-pid, SIGKILL);
                break;
            }
            wait_ms = int(left.count());
        }
        const int n = ::poll(fds, 2, wait_ms);
        if (n < 0 && errno != EINTR) break;
        for (int i = 0; i < 2; ++i) {
            if (fds[i].fd < 0 || !(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
            const ssize_t got = ::read(fds[i].fd, buf, sizeof buf);
            if (got > 0) {
                sinks[i]->append(buf, std::size_t(got));
            } else if (got == 0 || errno != EINTR) {
                ::close(fds[i].fd);
                fds[i].fd = -1;
                --open_fds;
            }
        }
    }
    for (pollfd& f : fds)
        if (f.fd >= 0) ::close(f.fd);
    int status = 0;
    rusage usage{};
    while (::wait4(pid, &status, 0, &usage) < 0 && errno == EINTR) {
    }
    r.cpu_seconds = double(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
                    double(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec) / 1e6;
    if (r.timed_out) ::kill(-pid, SIGKILL);  // helpers it started, if any survived
    r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (WIFEXITED(status))
        r.code = WEXITSTATUS(status);
    else if (WIFSIGNALED(status))
        r.signal = WTERMSIG(status);
    r.cpu_limited = o.cpu_seconds > 0 && !r.timed_out &&
                    (r.signal == SIGXCPU || (r.signal == SIGKILL && r.cpu_seconds >= o.cpu_seconds));
    return r;
}

/// A command line for /bin/sh, whose `exec` makes the command itself the child, so that its exit
/// status and signal are the command's own.
inline Outcome run_shell(const std::string& command, const RunOptions& o = {}) {
    return run_process({"/bin/sh", "-c", "exec " + command}, o);
}

}  // namespace test
