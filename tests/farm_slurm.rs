//! The Slurm farm scripts (`examples/farm/`) end to end on a one-node Slurm the test starts
//! itself from Debian's `slurm-wlm` and `munge`: `munged`, `slurmctld` and `slurmd` in the
//! foreground in a temporary folder, with their own key, socket, ports and state.
//!
//! Checked with `sacct` (reading the job completion log, `JobCompType=jobcomp/filetxt`: without
//! slurmdbd there is no accounting database, and `sacct --completion` reads that log instead):
//! every array task completed with the CPUs asked for; the merge started after the last task
//! ended; a failed task cancels the merge (`afterok` never met, `--kill-on-invalid-dep`).
//! The furrow stand-in `examples/farm/furrow-stub.sh` runs the chunks (fast, deterministic);
//! when this build's `furrow chunks` exists, a short real run on `rigs/face.glb` follows.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The programs the test runs; Debian puts the daemons in /usr/sbin.
const TOOLS: [&str; 8] = [
    "munged",
    "slurmctld",
    "slurmd",
    "sbatch",
    "sacct",
    "sinfo",
    "squeue",
    "scancel",
];

/// The node's name in slurm.conf (`slurmd -N` takes it; the address is 127.0.0.1).
const NODE: &str = "farm0";

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `name` on PATH or in /usr/sbin, /sbin.
fn find_tool(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/sbin"].map(PathBuf::from))
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// Whether the test can run here; prints why not (and fails under CI, where Slurm is installed
/// by `.ci/run` and the test must run).
fn slurm_usable() -> bool {
    let missing: Vec<&str> = TOOLS
        .into_iter()
        .filter(|t| find_tool(t).is_none())
        .collect();
    if !missing.is_empty() {
        assert!(
            !common::tools_required(),
            "Slurm is not installed (missing {missing:?}): apt-get install -y slurm-wlm munge (.ci/run does)"
        );
        common::note(&format!(
            "Slurm not installed ({}); farm test skipped (apt-get install -y slurm-wlm munge)",
            missing.join(", ")
        ));
        return false;
    }
    let uid = Command::new("id").arg("-u").output().expect("id runs");
    if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
        assert!(
            !common::tools_required(),
            "the farm test starts slurmd, which runs jobs as root: run CI as root"
        );
        common::note("not root (slurmd needs root); farm test skipped");
        return false;
    }
    true
}

/// A free TCP port on this machine (taken by the OS, then released for Slurm).
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind a port");
    l.local_addr().unwrap().port()
}

/// Run `cmd`, return its stdout; panics with its output when it fails.
fn run(cmd: &mut Command) -> String {
    let o = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    assert!(
        o.status.success(),
        "{cmd:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Wait until `ready` holds, polling every half second; None on timeout.
fn wait_for<T>(timeout: Duration, mut ready: impl FnMut() -> Option<T>) -> Option<T> {
    let start = Instant::now();
    loop {
        if let Some(v) = ready() {
            return Some(v);
        }
        if start.elapsed() > timeout {
            return None;
        }
        std::thread::sleep(Duration::from_millis(500));
    }
}

/// The one-node cluster: its folder, config and daemons. Dropping it cancels what is left in
/// its queue and stops the daemons (also when a check panics).
struct Cluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
    daemons: Vec<(&'static str, Child)>,
    /// MB of memory the node offers (real runs ask for all of it).
    memory_mb: u64,
}

impl Cluster {
    fn start() -> Cluster {
        use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
        let dir = tempfile::tempdir().expect("temp dir");
        // munged wants every folder on its socket's path open to all (0755).
        std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
        let d = dir.path().to_path_buf();
        for sub in ["munge", "state", "spool", "log", "jobs"] {
            std::fs::create_dir(d.join(sub)).unwrap();
        }
        let mut key = vec![0u8; 128];
        std::io::Read::read_exact(&mut std::fs::File::open("/dev/urandom").unwrap(), &mut key)
            .unwrap();
        let mut f = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(d.join("munge/munge.key"))
            .unwrap();
        std::io::Write::write_all(&mut f, &key).unwrap();
        drop(f);

        // The short host name, as slurmctld compares it with SlurmctldHost.
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname").expect("host name");
        let host = host.trim().split('.').next().unwrap().to_string();
        let memory_mb = node_memory_mb();
        let conf = d.join("slurm.conf");
        std::fs::write(&conf, slurm_conf(&d, &host, memory_mb)).unwrap();
        let mut c = Cluster {
            dir,
            conf,
            daemons: Vec::new(),
            memory_mb,
        };
        let socket = d.join("munge/munge.socket");
        c.spawn(
            "munged",
            &[
                "--foreground".into(),
                format!("--socket={}", socket.display()),
                format!("--key-file={}", d.join("munge/munge.key").display()),
                format!("--pid-file={}", d.join("munge/munged.pid").display()),
                format!("--seed-file={}", d.join("munge/munged.seed").display()),
                format!("--log-file={}", d.join("log/munged.log").display()),
            ],
        );
        if wait_for(Duration::from_secs(10), || socket.exists().then_some(())).is_none() {
            panic!("munged made no socket:\n{}", c.logs());
        }
        let conf_arg = c.conf.display().to_string();
        c.spawn(
            "slurmctld",
            &["-D".into(), "-i".into(), "-f".into(), conf_arg.clone()],
        );
        c.spawn(
            "slurmd",
            &["-D".into(), "-N".into(), NODE.into(), "-f".into(), conf_arg],
        );
        let idle = wait_for(Duration::from_secs(60), || {
            let o = c
                .cmd("sinfo")
                .args(["-h", "-N", "-o", "%t", "-n", NODE])
                .output()
                .ok()?;
            (String::from_utf8_lossy(&o.stdout).trim() == "idle").then_some(())
        });
        if idle.is_none() {
            panic!("the node did not come up idle in 60 s:\n{}", c.logs());
        }
        c
    }

    /// Start a daemon with its output in log/NAME.out.
    fn spawn(&mut self, name: &'static str, args: &[String]) {
        let out = std::fs::File::create(self.dir.path().join(format!("log/{name}.out"))).unwrap();
        let child = Command::new(find_tool(name).unwrap())
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .stdin(Stdio::null())
            .stdout(out.try_clone().unwrap())
            .stderr(out)
            .spawn()
            .unwrap_or_else(|e| panic!("{name} does not start: {e}"));
        self.daemons.push((name, child));
    }

    /// A Slurm client command talking to this cluster.
    fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(find_tool(program).unwrap());
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// The daemons' logs and the queue, for a failure message.
    fn logs(&self) -> String {
        let mut s = String::new();
        for name in [
            "munged.out",
            "slurmctld.log",
            "slurmd.log",
            "slurmctld.out",
            "slurmd.out",
        ] {
            let text =
                std::fs::read_to_string(self.dir.path().join("log").join(name)).unwrap_or_default();
            let tail: Vec<&str> = text.lines().rev().take(25).collect();
            s += &format!("--- {name} (last lines)\n");
            for l in tail.into_iter().rev() {
                s += l;
                s.push('\n');
            }
        }
        if let Ok(o) = self.cmd("squeue").args(["-o", "%i %j %T %r"]).output() {
            s += &format!("--- squeue\n{}", String::from_utf8_lossy(&o.stdout));
        }
        s
    }

    /// Run `examples/farm/submit.sh RIG OUT COUNT PREROLL` with `env`; returns the array
    /// and merge job ids it printed.
    fn submit(&self, out: &Path, rig: &Path, count: usize, env: &[(&str, String)]) -> (u64, u64) {
        let mut c = Command::new("bash");
        c.arg(root().join("examples/farm/submit.sh"))
            .arg(rig)
            .arg(out)
            .arg(count.to_string())
            .arg("1")
            .env("SLURM_CONF", &self.conf);
        for (k, v) in env {
            c.env(k, v);
        }
        let text = run(&mut c);
        let id = |key: &str| -> u64 {
            text.lines()
                .find_map(|l| l.strip_prefix(key)?.trim().parse().ok())
                .unwrap_or_else(|| panic!("submit.sh printed no `{key}JOBID`: {text}"))
        };
        (id("array "), id("merge "))
    }

    /// The finished jobs that ran in `out` (submit.sh's --chdir), once the merge job and
    /// `count` chunk tasks are all in the completion log.
    fn finished(&self, out: &Path, count: usize, timeout: Duration) -> Jobs {
        let jobs = wait_for(timeout, || {
            let j = self.sacct(out);
            (j.merge.is_some() && j.chunks.len() >= count).then_some(j)
        });
        jobs.unwrap_or_else(|| {
            panic!(
                "the jobs in {} did not finish in {timeout:?}: {:?}\n{}",
                out.display(),
                self.sacct(out),
                self.logs()
            )
        })
    }

    /// What `sacct --completion` says about the jobs that ran in `out`.
    fn sacct(&self, out: &Path) -> Jobs {
        // sacct warns on stderr about the log's ArrayJobId/ArrayTaskId fields it does not
        // parse; the job ids it prints are the tasks' own.
        let text = run(self.cmd("sacct").args([
            "--completion",
            "--parsable2",
            "--noheader",
            "--format=JobID,JobName,State,Start,End,AllocCPUS,WorkDir",
        ]));
        let mut jobs = Jobs::default();
        for l in text.lines() {
            let f: Vec<&str> = l.split('|').collect();
            if f.len() != 7 || Path::new(f[6]) != out {
                continue;
            }
            let job = Job {
                id: f[0].parse().unwrap_or(0),
                state: f[2].to_string(),
                start: f[3].to_string(),
                end: f[4].to_string(),
                cpus: f[5].parse().unwrap_or(0),
            };
            match f[1] {
                "furrow-chunk" => jobs.chunks.push(job),
                "furrow-merge" => jobs.merge = Some(job),
                _ => {}
            }
        }
        jobs
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // Nothing should be left; after a failed check, cancel it before stopping slurmd.
        if let Ok(o) = self.cmd("squeue").args(["-h", "-o", "%A"]).output() {
            let ids: Vec<String> = String::from_utf8_lossy(&o.stdout)
                .split_whitespace()
                .map(String::from)
                .collect();
            if !ids.is_empty() {
                let _ = self.cmd("scancel").args(&ids).status();
                std::thread::sleep(Duration::from_secs(1));
            }
        }
        // slurmd, slurmctld, munged: SIGTERM, then SIGKILL after 10 s.
        for (_, child) in self.daemons.iter_mut().rev() {
            let _ = Command::new("kill")
                .args(["-TERM", &child.id().to_string()])
                .status();
            let stopped = wait_for(Duration::from_secs(10), || {
                child.try_wait().ok().flatten().map(|_| ())
            });
            if stopped.is_none() {
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
}

/// One job as `sacct` reports it (times as `YYYY-MM-DDTHH:MM:SS`, comparable as text).
#[derive(Debug, Clone)]
struct Job {
    id: u64,
    state: String,
    start: String,
    end: String,
    cpus: u32,
}

/// The jobs of one submission.
#[derive(Debug, Default)]
struct Jobs {
    chunks: Vec<Job>,
    merge: Option<Job>,
}

/// Half the machine's memory, at most 8 GB, in MB (the node's RealMemory).
fn node_memory_mb() -> u64 {
    let info = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
    let kb: u64 = info
        .lines()
        .find_map(|l| l.strip_prefix("MemTotal:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(2 << 20);
    (kb / 1024 / 2).clamp(512, 8192)
}

/// A minimal slurm.conf: one node with 2 CPUs at 127.0.0.1, everything in `d`, no slurmdbd
/// (the job completion log stands in for accounting).
fn slurm_conf(d: &Path, host: &str, memory_mb: u64) -> String {
    let p = |s: &str| d.join(s).display().to_string();
    format!(
        "\
ClusterName=furrowtest
SlurmctldHost={host}(127.0.0.1)
SlurmctldPort={ctld}
SlurmdPort={slurmd}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket}
MpiDefault=none
MailProg=/bin/true
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU_Memory
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc={jobcomp}
StateSaveLocation={state}
SlurmdSpoolDir={spool}
SlurmctldPidFile={ctld_pid}
SlurmdPidFile={slurmd_pid}
SlurmctldLogFile={ctld_log}
SlurmdLogFile={slurmd_log}
ReturnToService=2
NodeName={NODE} NodeAddr=127.0.0.1 CPUs=2 RealMemory={memory_mb} State=UNKNOWN
PartitionName=farm Nodes={NODE} Default=YES MaxTime=INFINITE State=UP
",
        ctld = free_port(),
        slurmd = free_port(),
        socket = p("munge/munge.socket"),
        jobcomp = p("log/jobcomp.txt"),
        state = p("state"),
        spool = p("spool"),
        ctld_pid = p("slurmctld.pid"),
        slurmd_pid = p("slurmd.pid"),
        ctld_log = p("log/slurmctld.log"),
        slurmd_log = p("log/slurmd.log"),
    )
}

/// Every chunk task completed with `cpus` CPUs and the merge completed after the last one.
fn assert_completed_in_order(jobs: &Jobs, count: usize, cpus: u32) {
    assert_eq!(jobs.chunks.len(), count, "chunk tasks: {jobs:?}");
    for t in &jobs.chunks {
        assert_eq!(t.state, "COMPLETED", "chunk task {t:?}");
        assert_eq!(t.cpus, cpus, "chunk task's CPUs (--cpus-per-task): {t:?}");
    }
    let merge = jobs.merge.as_ref().unwrap();
    assert_eq!(merge.state, "COMPLETED", "merge {merge:?}");
    let last_end = jobs.chunks.iter().map(|t| t.end.as_str()).max().unwrap();
    assert!(
        merge.start.as_str() >= last_end,
        "the merge started at {} before the last chunk task ended at {last_end}: {jobs:?}",
        merge.start
    );
}

/// The stand-in furrow: the array of 4 chunks then the merge; and a second submission whose
/// second chunk fails, which cancels its merge. Then, when this build has `furrow chunks`, a
/// real run.
#[test]
fn slurm_array_then_dependent_merge() {
    if !slurm_usable() {
        return;
    }
    let started = Instant::now();
    let cluster = Cluster::start();
    let jobs_dir = cluster.dir.path().join("jobs");
    let rig = root().join("rigs/face.glb");
    let stub = root().join("examples/farm/furrow-stub.sh");
    let count = 4;
    let env = |cpus: u32| {
        vec![
            ("FURROW", stub.display().to_string()),
            ("FARM_CPUS", cpus.to_string()),
            ("FARM_MEM", "100M".to_string()),
            ("FARM_MERGE_CPUS", "1".to_string()),
            ("FARM_MERGE_MEM", "100M".to_string()),
        ]
    };
    // Both submissions at once: each merge waits for its own array only.
    let ok = jobs_dir.join("ok");
    let (_, ok_merge) = cluster.submit(&ok, &rig, count, &env(2));
    let failing = jobs_dir.join("failing");
    let ranges = |out: &Path| -> Vec<String> {
        std::fs::read_to_string(out.join("ranges.txt"))
            .unwrap()
            .lines()
            .map(String::from)
            .collect()
    };
    // The stub splits 12 frames into 0:3 3:6 6:9 9:12; the second chunk fails.
    let mut fail_env = env(1);
    fail_env.push(("FURROW_FAIL_RANGE", "3:6".to_string()));
    let (_, failing_merge) = cluster.submit(&failing, &rig, count, &fail_env);
    assert_eq!(ranges(&failing)[1], "3:6");

    let timeout = Duration::from_secs(120);
    let jobs = cluster.finished(&ok, count, timeout);
    assert_completed_in_order(&jobs, count, 2);
    assert_eq!(jobs.merge.as_ref().unwrap().id, ok_merge);
    // The merge joined every chunk in order; each task had RAYON_NUM_THREADS from its CPUs.
    let merged = std::fs::read_to_string(ok.join("face_wrinkled.glb")).unwrap();
    let expected: Vec<String> = ranges(&ok)
        .iter()
        .enumerate()
        .map(|(i, r)| format!("frames={r} preroll=1 threads=2 task={i}"))
        .collect();
    assert_eq!(merged.lines().collect::<Vec<_>>(), expected);
    assert!(ok.join("merge.json").is_file());

    let jobs = cluster.finished(&failing, count, timeout);
    let states: BTreeMap<&str, usize> = jobs.chunks.iter().fold(BTreeMap::new(), |mut m, t| {
        *m.entry(t.state.as_str()).or_default() += 1;
        m
    });
    assert_eq!(
        states,
        BTreeMap::from([("COMPLETED", count - 1), ("FAILED", 1)]),
        "{jobs:?}"
    );
    let merge = jobs.merge.as_ref().unwrap();
    assert_eq!(merge.id, failing_merge);
    // Cancelled without running: no CPUs given, no log, no output.
    assert_eq!(
        (merge.state.as_str(), merge.cpus),
        ("CANCELLED", 0),
        "{jobs:?}"
    );
    assert!(!failing.join("face_wrinkled.glb").exists());
    assert!(!failing
        .join(format!("logs/merge_{failing_merge}.out"))
        .exists());
    common::note(&format!(
        "stand-in farm runs checked in {:.0} s",
        started.elapsed().as_secs_f64()
    ));

    real_run(&cluster, &rig);
}

/// Two chunks of a few frames of rigs/face.glb with this build's furrow, merged; skipped with
/// a note while `furrow chunks` (or its `--frames`) does not exist.
fn real_run(cluster: &Cluster, rig: &Path) {
    let furrow = env!("CARGO_BIN_EXE_furrow");
    let help = Command::new(furrow).args(["chunks", "--help"]).output();
    let help = match help {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).into_owned(),
        _ => {
            common::note("this furrow has no `chunks` command; real farm run skipped");
            return;
        }
    };
    if !help.contains("--frames") {
        common::note("`furrow chunks` has no --frames; real farm run (a short clip) skipped");
        return;
    }
    let started = Instant::now();
    let out = cluster.dir.path().join("jobs/real");
    let mem = format!("{}M", cluster.memory_mb);
    let env = [
        ("FURROW", furrow.to_string()),
        ("FARM_FRAMES", "0:4".to_string()),
        ("FARM_CPUS", "1".to_string()),
        ("FARM_MEM", mem.clone()),
        ("FARM_MERGE_CPUS", "1".to_string()),
        ("FARM_MERGE_MEM", mem),
    ];
    cluster.submit(&out, rig, 2, &env);
    let jobs = cluster.finished(&out, 2, Duration::from_secs(240));
    assert_completed_in_order(&jobs, 2, 1);
    let glb = std::fs::read(out.join("face_wrinkled.glb")).unwrap();
    assert_eq!(&glb[..4], b"glTF", "the merged file is a GLB");
    common::note(&format!(
        "real farm run (2 chunks of frames 0:4) checked in {:.0} s",
        started.elapsed().as_secs_f64()
    ));
}
