//! Instructions per call of chosen functions of a program, counted by single-stepping them.
//!
//! valgrind runs AVX2 at most, so its counts of a tracer that picks its AVX-512 path at run time
//! describe another program than the one a Xeon runs. This runs the program itself (on any CPU
//! with the instruction set the path needs, such as the 2-core VM's Zen 4) under ptrace, stops
//! at a breakpoint at each chosen address of the main executable, and for every N-th call steps
//! it instruction by instruction until it returns: an exact count of that call's instructions on
//! that path, callees included, and a histogram of the addresses stepped through.
//!
//! ```text
//! stepcount [--every N] [--max M] [--out FILE] --at OFF[:LEN][,OFF[:LEN]...] -- PROGRAM ARGS...
//! ```
//! - `OFF`: hexadecimal offset in the main executable (as `nm` prints it for a PIE) of a
//!   function's entry, or, with `:LEN`, of a call instruction LEN bytes long: the call to a
//!   shared library's function through the GOT (`call *...(%rip)`), counted from the call to
//!   the instruction after it.
//! - `--every N`: step every N-th call (counted over all addresses), let the others run (default 1);
//!   `--max M`: step at most M calls, then let the program run on (default: all).
//! - `--out FILE` (default `stepcount.txt`): `address count` per line, addresses in the main
//!   executable as offsets, others absolute, after a header that gives the stepped calls and
//!   the program's executable mappings (`tools/scripts/callgrind-inlined.py` reads it).
//!
//! Per address it prints to standard error the calls stepped and the instructions per call.
//! Pin the program to one CPU (`taskset -c 0`) and one worker so that the calls come in one
//! order. About 50,000 steps a second on the VM: 3,000 calls of 1,300 instructions take 80 s.
//! A string instruction with a `rep` prefix counts once per repetition.

use std::collections::HashMap;
use std::ffi::CString;
use std::process::ExitCode;

struct Options {
    every: u64,
    max: u64,
    out: String,
    at: Vec<(u64, u64)>,
    program: Vec<CString>,
}

fn options() -> Result<Options, String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let sep = args.iter().position(|a| a == "--").ok_or("give the program to run after `--`")?;
    let mut o = Options { every: 1, max: u64::MAX, out: "stepcount.txt".into(), at: Vec::new(), program: Vec::new() };
    let mut i = 0;
    while i < sep {
        let value = args.get(i + 1).filter(|_| i + 1 < sep).ok_or_else(|| format!("{} needs a value", args[i]))?;
        let number = |v: &str| v.parse::<u64>().map_err(|_| format!("{} takes a number, not `{v}`", args[i]));
        match args[i].as_str() {
            "--every" => o.every = number(value)?.max(1),
            "--max" => o.max = number(value)?,
            "--out" => o.out = value.clone(),
            "--at" => {
                for item in value.split(',') {
                    let (off, len) = item.split_once(':').unwrap_or((item, "0"));
                    let off = u64::from_str_radix(off.trim_start_matches("0x"), 16)
                        .map_err(|_| format!("--at takes hexadecimal offsets, not `{off}`"))?;
                    let len = len.parse().map_err(|_| format!("a call's length is a number, not `{len}`"))?;
                    o.at.push((off, len));
                }
            }
            other => return Err(format!("unknown option `{other}`")),
        }
        i += 2;
    }
    if o.at.is_empty() {
        return Err("give the addresses to count with --at".into());
    }
    o.program = args[sep + 1..]
        .iter()
        .map(|a| CString::new(a.as_str()).map_err(|_| "an argument holds a NUL byte".to_string()))
        .collect::<Result<_, _>>()?;
    if o.program.is_empty() {
        return Err("give the program to run after `--`".into());
    }
    Ok(o)
}

fn peek(pid: i32, addr: u64) -> u64 {
    // SAFETY: PEEKDATA reads the stopped tracee's memory; errors come back as -1 (a word we never need).
    unsafe {
        libc::ptrace(libc::PTRACE_PEEKDATA, pid, addr as *mut libc::c_void, std::ptr::null_mut::<libc::c_void>()) as u64
    }
}

fn poke(pid: i32, addr: u64, word: u64) {
    // SAFETY: as `peek`, writing one word of the stopped tracee's code.
    unsafe { libc::ptrace(libc::PTRACE_POKEDATA, pid, addr as *mut libc::c_void, word as *mut libc::c_void) };
}

fn registers(pid: i32) -> libc::user_regs_struct {
    // SAFETY: a plain-data struct the kernel fills.
    let mut r: libc::user_regs_struct = unsafe { std::mem::zeroed() };
    // SAFETY: GETREGS of a stopped tracee into a struct of the right type.
    unsafe { libc::ptrace(libc::PTRACE_GETREGS, pid, 0, &mut r as *mut _ as *mut libc::c_void) };
    r
}

fn set_registers(pid: i32, r: &libc::user_regs_struct) {
    // SAFETY: as `registers`.
    unsafe { libc::ptrace(libc::PTRACE_SETREGS, pid, 0, r as *const _ as *mut libc::c_void) };
}

fn resume(pid: i32, request: libc::c_uint, signal: i32) {
    // SAFETY: resumes a stopped tracee (CONT or SINGLESTEP), delivering `signal` (0: none).
    unsafe { libc::ptrace(request, pid, 0, signal as usize as *mut libc::c_void) };
}

/// A breakpoint: `int3` over the first byte of the word at `addr`.
struct Breakpoint {
    addr: u64,
    word: u64,
    /// 0 for a function entry (the call returns to the address on the stack), else the length of
    /// the call instruction at `addr`.
    call_len: u64,
}

impl Breakpoint {
    fn arm(&self, pid: i32) {
        poke(pid, self.addr, (self.word & !0xff) | 0xcc);
    }
    fn disarm(&self, pid: i32) {
        poke(pid, self.addr, self.word);
    }
}

/// What a thread of the tracee is doing.
enum Thread {
    Running,
    /// Stepping over the instruction under a disarmed breakpoint, to arm it again.
    Rearming(usize),
    /// Stepping a counted call: it ends at `ret` with the stack pointer at least `sp`.
    Counting {
        bp: usize,
        ret: u64,
        sp: u64,
        steps: u64,
    },
}

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("stepcount: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let o = options()?;
    // SAFETY: the child only calls async-signal-safe functions before exec.
    let child = unsafe { libc::fork() };
    if child < 0 {
        return Err("could not fork".into());
    }
    if child == 0 {
        let mut argv: Vec<*const libc::c_char> = o.program.iter().map(|c| c.as_ptr()).collect();
        argv.push(std::ptr::null());
        // SAFETY: TRACEME then exec with a NUL-terminated argv of live CStrings.
        unsafe {
            libc::ptrace(libc::PTRACE_TRACEME, 0, 0, 0);
            libc::execvp(argv[0], argv.as_ptr());
            libc::_exit(127);
        }
    }
    let mut status = 0;
    // SAFETY: waits for the child's stop at exec.
    unsafe { libc::waitpid(child, &mut status, 0) };
    if !libc::WIFSTOPPED(status) {
        return Err(format!("{} did not start", o.program[0].to_string_lossy()));
    }
    let options = libc::PTRACE_O_TRACECLONE | libc::PTRACE_O_EXITKILL;
    // SAFETY: options of our stopped tracee.
    unsafe { libc::ptrace(libc::PTRACE_SETOPTIONS, child, 0, options as usize as *mut libc::c_void) };
    let exe =
        std::fs::read_link(format!("/proc/{child}/exe")).map_err(|e| format!("reading the program's path: {e}"))?;
    let maps =
        std::fs::read_to_string(format!("/proc/{child}/maps")).map_err(|e| format!("reading its mappings: {e}"))?;
    let base = maps
        .lines()
        .find(|l| l.ends_with(&*exe.to_string_lossy()))
        .and_then(|l| u64::from_str_radix(l.split('-').next()?, 16).ok())
        .ok_or("the program's executable is not mapped")?;
    let bps: Vec<Breakpoint> =
        o.at.iter()
            .map(|&(off, call_len)| Breakpoint { addr: base + off, word: peek(child, base + off), call_len })
            .collect();
    for b in &bps {
        b.arm(child);
    }
    let mut threads: HashMap<i32, Thread> = HashMap::from([(child, Thread::Running)]);
    let (mut calls, mut stepped) = (0u64, 0u64);
    let mut per_bp = vec![(0u64, 0u64); bps.len()];
    let mut histogram: HashMap<u64, u64> = HashMap::new();
    // The mappings once the libraries are loaded (at the first counted call).
    let mut mappings = String::new();
    resume(child, libc::PTRACE_CONT, 0);
    loop {
        // SAFETY: waits for any of the tracee's threads.
        let tid = unsafe { libc::waitpid(-1, &mut status, libc::__WALL) };
        if tid < 0 {
            break;
        }
        if libc::WIFEXITED(status) || libc::WIFSIGNALED(status) {
            threads.remove(&tid);
            if tid == child {
                break;
            }
            continue;
        }
        if !libc::WIFSTOPPED(status) {
            continue;
        }
        let (signal, event) = (libc::WSTOPSIG(status), status >> 16);
        let new_thread = !threads.contains_key(&tid);
        let thread = threads.entry(tid).or_insert(Thread::Running);
        if event == libc::PTRACE_EVENT_CLONE || (signal == libc::SIGSTOP && new_thread) {
            resume(tid, libc::PTRACE_CONT, 0);
            continue;
        }
        if signal != libc::SIGTRAP {
            resume(tid, libc::PTRACE_CONT, signal);
            continue;
        }
        match *thread {
            Thread::Counting { bp, ret, sp, steps } => {
                let r = registers(tid);
                if r.rip == ret && r.rsp >= sp {
                    per_bp[bp].0 += 1;
                    per_bp[bp].1 += steps;
                    stepped += 1;
                    *thread = Thread::Running;
                    if stepped < o.max {
                        bps[bp].arm(tid);
                    }
                    resume(tid, libc::PTRACE_CONT, 0);
                } else {
                    *histogram.entry(r.rip).or_default() += 1;
                    *thread = Thread::Counting { bp, ret, sp, steps: steps + 1 };
                    resume(tid, libc::PTRACE_SINGLESTEP, 0);
                }
            }
            Thread::Rearming(bp) => {
                bps[bp].arm(tid);
                *thread = Thread::Running;
                resume(tid, libc::PTRACE_CONT, 0);
            }
            Thread::Running => {
                let mut r = registers(tid);
                let Some(k) = bps.iter().position(|b| b.addr == r.rip.wrapping_sub(1)) else {
                    resume(tid, libc::PTRACE_CONT, signal);
                    continue;
                };
                bps[k].disarm(tid);
                r.rip -= 1;
                set_registers(tid, &r);
                calls += 1;
                *thread = if calls % o.every == 0 && stepped < o.max {
                    if mappings.is_empty() {
                        mappings = std::fs::read_to_string(format!("/proc/{child}/maps")).unwrap_or_default();
                    }
                    *histogram.entry(r.rip).or_default() += 1;
                    let (ret, sp) = match bps[k].call_len {
                        0 => (peek(tid, r.rsp), r.rsp + 8),
                        len => (r.rip + len, r.rsp),
                    };
                    Thread::Counting { bp: k, ret, sp, steps: 1 }
                } else {
                    Thread::Rearming(k)
                };
                resume(tid, libc::PTRACE_SINGLESTEP, 0);
            }
        }
    }
    let total: u64 = per_bp.iter().map(|p| p.1).sum();
    eprintln!("stepcount: {calls} calls, {stepped} stepped, {total} instructions");
    for ((off, _), (n, steps)) in o.at.iter().zip(&per_bp) {
        eprintln!(
            "stepcount: at {off:#x}: {n} calls stepped, {:.1} instructions per call",
            *steps as f64 / (*n).max(1) as f64
        );
    }
    let mut rows: Vec<_> = histogram.into_iter().collect();
    rows.sort_unstable();
    let mut text = format!("# stepcount base {base:#x} stepped {stepped} instructions {total}\n");
    for line in mappings.lines().filter(|l| l.contains(" r-xp ")) {
        text.push_str(&format!("# map {line}\n"));
    }
    for (addr, n) in rows {
        let addr = if (base..base + (1 << 32)).contains(&addr) { addr - base } else { addr };
        text.push_str(&format!("{addr:#x} {n}\n"));
    }
    std::fs::write(&o.out, text).map_err(|e| format!("writing {}: {e}", o.out))
}
