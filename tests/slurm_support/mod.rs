//! A private single-node Slurm cluster for tests, from Debian's packages (`munge`, `slurmctld`,
//! `slurmd`, `slurm-client`): a munge daemon with a fresh key, slurmctld and slurmd on free ports,
//! one node (this host, its real CPUs and memory), all files in a temporary folder. `start` waits
//! until `sinfo` shows the node idle; dropping the cluster cancels its jobs, stops the daemons and
//! removes the folder. Where Slurm cannot start here (not root, packages missing, a container that
//! forbids something) `start` returns the reason; `start_or_skip` prints it and the test skips,
//! unless `DAMAGE_TWIN_REQUIRE_SLURM=1` (CI) makes that a failure. docs/CLUSTER_TESTING.md.
// Each test uses some of these.
#![allow(dead_code)]

use std::fmt;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// Why the cluster could not start (printed by a skipping test).
#[derive(Debug)]
pub struct SkipReason(pub String);

impl fmt::Display for SkipReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// How a job submitted with `submit_and_wait` ended.
#[derive(Debug)]
pub struct JobOutcome {
    pub job_id: u64,
    /// `sbatch --wait`'s exit status: 0 when every task of the job succeeded.
    pub exit_code: i32,
    pub stdout: String,
    pub stderr: String,
}

pub struct SlurmCluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
    /// munged, slurmctld, slurmd, in start order.
    daemons: Vec<(&'static str, Child)>,
    pub node: String,
    pub cpus: u32,
}

const DAEMONS: [&str; 3] = [
    "/usr/sbin/munged",
    "/usr/sbin/slurmctld",
    "/usr/sbin/slurmd",
];
const CLIENTS: [&str; 5] = ["sbatch", "sinfo", "scancel", "squeue", "scontrol"];
/// How long the daemons get to bring the node up (measured: about 2 s).
const START_TIMEOUT: Duration = Duration::from_secs(30);

impl SlurmCluster {
    /// Starts the cluster, or says why it cannot here.
    pub fn start() -> Result<SlurmCluster, SkipReason> {
        let skip = |m: String| Err(SkipReason(m));
        if !is_root() {
            return skip("not root: slurmd must run as root to launch jobs".to_string());
        }
        for daemon in DAEMONS {
            if !Path::new(daemon).exists() {
                return skip(format!(
                    "{daemon} missing (apt-get install munge slurmctld slurmd slurm-client)"
                ));
            }
        }
        for client in CLIENTS {
            if find_in_path(client).is_none() {
                return skip(format!("{client} missing (apt-get install slurm-client)"));
            }
        }
        let dir = tempfile::Builder::new()
            .prefix("damage-twin-slurm-")
            .tempdir()
            .map_err(|e| SkipReason(format!("temporary folder: {e}")))?;
        let node = node_config().map_err(SkipReason)?;
        let mut cluster = SlurmCluster {
            conf: dir.path().join("slurm.conf"),
            dir,
            daemons: Vec::new(),
            node: node.name.clone(),
            cpus: node.cpus,
        };
        // Errors from here on tear down what was started (Drop).
        cluster.start_munge()?;
        cluster.write_conf(&node)?;
        let conf = cluster.conf.clone();
        cluster.spawn(
            "slurmctld",
            Command::new(DAEMONS[1]).args(["-D", "-i", "-f"]).arg(&conf),
        )?;
        cluster.spawn(
            "slurmd",
            Command::new(DAEMONS[2])
                .args(["-D", "-N", &node.name, "-f"])
                .arg(&conf),
        )?;
        cluster.wait_idle()?;
        Ok(cluster)
    }

    /// `start`, or `None` after printing why the test skips; with `DAMAGE_TWIN_REQUIRE_SLURM=1`
    /// a cluster that cannot start fails the test instead.
    pub fn start_or_skip(test: &str) -> Option<SlurmCluster> {
        let started = Instant::now();
        match SlurmCluster::start() {
            Ok(cluster) => {
                eprintln!(
                    "{test}: Slurm node {} ({} CPUs) idle after {:.1} s",
                    cluster.node,
                    cluster.cpus,
                    started.elapsed().as_secs_f64()
                );
                Some(cluster)
            }
            Err(reason) => {
                if std::env::var("DAMAGE_TWIN_REQUIRE_SLURM").as_deref() == Ok("1") {
                    panic!("{test}: Slurm is required here but cannot start: {reason}");
                }
                eprintln!("skipping {test}: Slurm cannot start here: {reason}");
                None
            }
        }
    }

    /// The cluster's folder (shared storage for its jobs: every node is this host).
    pub fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// A Slurm client command (`sbatch`, `sinfo`, ...) pointed at this cluster.
    pub fn command(&self, program: &str) -> Command {
        let mut command = Command::new(program);
        // A submitting shell's own job variables must not leak into the test's jobs.
        for (key, _) in std::env::vars() {
            if key.starts_with("SLURM_") || key.starts_with("SBATCH_") {
                command.env_remove(key);
            }
        }
        command.env("SLURM_CONF", &self.conf);
        command
    }

    /// Submits `script` with `sbatch --wait` (plus `args`, e.g. `--array=0-2`) and returns when
    /// every task has ended; `Err` when sbatch could not submit at all.
    pub fn submit_and_wait(&self, script: &Path, args: &[&str]) -> Result<JobOutcome, String> {
        let output = self
            .command("sbatch")
            .arg("--wait")
            .arg("--parsable")
            .args(args)
            .arg(script)
            .current_dir(self.dir())
            .output()
            .map_err(|e| format!("running sbatch: {e}"))?;
        let stdout = String::from_utf8_lossy(&output.stdout).to_string();
        let stderr = String::from_utf8_lossy(&output.stderr).to_string();
        // --parsable prints "JOBID" or "JOBID;CLUSTER" first.
        let job_id = stdout
            .lines()
            .next()
            .and_then(|l| l.split(';').next())
            .and_then(|id| id.trim().parse().ok())
            .ok_or_else(|| {
                format!(
                    "sbatch {} did not submit: {}{}",
                    script.display(),
                    stderr.trim(),
                    self.logs()
                )
            })?;
        Ok(JobOutcome {
            job_id,
            exit_code: output.status.code().unwrap_or(-1),
            stdout,
            stderr,
        })
    }

    /// Waits until job `job_id` (all its array tasks) has left the queue, polling every 0.2 s,
    /// and returns each record's `JobState` and `ExitCode` from `scontrol show job` (kept for
    /// `MinJobAge`, 60 s): for a job submitted by something else, e.g. a dependent merge job.
    pub fn wait_for_job(
        &self,
        job_id: u64,
        timeout: Duration,
    ) -> Result<Vec<(String, String)>, String> {
        let start = Instant::now();
        let id = job_id.to_string();
        loop {
            let queued = self
                .command("squeue")
                .args(["-h", "-j", &id, "-o", "%T"])
                .output()
                .map_err(|e| format!("squeue: {e}"))?;
            let states = String::from_utf8_lossy(&queued.stdout).to_string();
            if queued.status.success() && states.trim().is_empty() {
                break;
            }
            if start.elapsed() > timeout {
                return Err(format!(
                    "job {job_id} still queued after {timeout:?}: {}",
                    states.trim()
                ));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        let shown = self
            .command("scontrol")
            .args(["show", "job", &id, "--oneliner"])
            .output()
            .map_err(|e| format!("scontrol: {e}"))?;
        let text = String::from_utf8_lossy(&shown.stdout);
        let field = |line: &str, key: &str| {
            line.split_whitespace()
                .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
                .unwrap_or("")
                .to_string()
        };
        let records: Vec<(String, String)> = text
            .lines()
            .filter(|l| l.contains("JobState="))
            .map(|l| (field(l, "JobState"), field(l, "ExitCode")))
            .collect();
        if records.is_empty() {
            return Err(format!("scontrol show job {job_id}: {}", text.trim()));
        }
        Ok(records)
    }

    /// The tails of the daemons' logs, for failure messages.
    pub fn logs(&self) -> String {
        let mut out = String::new();
        for name in ["munged.log", "slurmctld.log", "slurmd.log"] {
            let text = std::fs::read_to_string(self.dir().join(name)).unwrap_or_default();
            let lines: Vec<&str> = text.lines().collect();
            let tail = &lines[lines.len().saturating_sub(8)..];
            out.push_str(&format!("\n--- {name} ---\n{}", tail.join("\n")));
        }
        out
    }

    fn start_munge(&mut self) -> Result<(), SkipReason> {
        let key = self.dir().join("munge.key");
        let mut bytes = [0u8; 1024];
        std::fs::File::open("/dev/urandom")
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut bytes))
            .and_then(|()| std::fs::write(&key, bytes))
            .map_err(|e| SkipReason(format!("writing the munge key: {e}")))?;
        set_mode(&key, 0o400)?;
        let dir = self.dir().to_path_buf();
        self.spawn(
            "munged",
            Command::new(DAEMONS[0])
                .arg("--foreground")
                // munged refuses to run as root without it; the test cluster runs all as root.
                .arg("--force")
                .arg(format!("--key-file={}", key.display()))
                .arg(format!("--socket={}", dir.join("munge.socket").display()))
                .arg(format!("--pid-file={}", dir.join("munged.pid").display()))
                .arg(format!("--log-file={}", dir.join("munged.log").display()))
                .arg(format!("--seed-file={}", dir.join("munged.seed").display())),
        )?;
        let socket = dir.join("munge.socket");
        let start = Instant::now();
        while !socket.exists() {
            self.check_alive()?;
            if start.elapsed() > START_TIMEOUT {
                return Err(SkipReason(format!("munged did not start{}", self.logs())));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        Ok(())
    }

    fn write_conf(&self, node: &NodeConfig) -> Result<(), SkipReason> {
        let d = self.dir();
        for sub in ["state", "spool"] {
            std::fs::create_dir_all(d.join(sub))
                .map_err(|e| SkipReason(format!("{}: {e}", d.join(sub).display())))?;
        }
        let (ctld_port, slurmd_port) = (free_port()?, free_port()?);
        let p = |name: &str| d.join(name).display().to_string();
        let text = format!(
            "# A single-node test cluster (tests/slurm_support).
ClusterName=damagetwin
SlurmctldHost={name}(127.0.0.1)
SlurmctldPort={ctld_port}
SlurmdPort={slurmd_port}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket={socket}
StateSaveLocation={state}
SlurmdSpoolDir={spool}
SlurmctldPidFile={ctld_pid}
SlurmdPidFile={slurmd_pid}
SlurmctldLogFile={ctld_log}
SlurmdLogFile={slurmd_log}
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
MpiDefault=none
ReturnToService=2
SlurmdParameters=config_overrides
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=60
KillWait=5
NodeName={name} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={memory} State=UNKNOWN
PartitionName=test Nodes={name} Default=YES MaxTime=INFINITE State=UP
",
            name = node.name,
            cpus = node.cpus,
            memory = node.memory_mb,
            socket = p("munge.socket"),
            state = p("state"),
            spool = p("spool"),
            ctld_pid = p("slurmctld.pid"),
            slurmd_pid = p("slurmd.pid"),
            ctld_log = p("slurmctld.log"),
            slurmd_log = p("slurmd.log"),
        );
        std::fs::write(&self.conf, text)
            .map_err(|e| SkipReason(format!("{}: {e}", self.conf.display())))
    }

    fn spawn(&mut self, name: &'static str, command: &mut Command) -> Result<(), SkipReason> {
        let child = command
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(
                std::fs::File::create(self.dir().join(format!("{name}.stderr")))
                    .map_or_else(|_| Stdio::null(), Stdio::from),
            )
            .spawn()
            .map_err(|e| SkipReason(format!("starting {name}: {e}")))?;
        self.daemons.push((name, child));
        Ok(())
    }

    /// A daemon that exited already (bad config, container limits) is a reason to skip.
    fn check_alive(&mut self) -> Result<(), SkipReason> {
        let exited = self
            .daemons
            .iter_mut()
            .find_map(|(name, child)| Some((*name, child.try_wait().ok()??)));
        if let Some((name, status)) = exited {
            {
                let stderr =
                    std::fs::read_to_string(self.dir.path().join(format!("{name}.stderr")))
                        .unwrap_or_default();
                return Err(SkipReason(format!(
                    "{name} exited ({status}): {}{}",
                    stderr.trim(),
                    self.logs()
                )));
            }
        }
        Ok(())
    }

    fn wait_idle(&mut self) -> Result<(), SkipReason> {
        let start = Instant::now();
        let mut last = String::new();
        loop {
            self.check_alive()?;
            if let Ok(out) = self
                .command("sinfo")
                .args(["-h", "-N", "-o", "%T"])
                .output()
            {
                last = String::from_utf8_lossy(&out.stdout).trim().to_string();
                if last == "idle" {
                    return Ok(());
                }
            }
            if start.elapsed() > START_TIMEOUT {
                return Err(SkipReason(format!(
                    "the node did not become idle in {} s (sinfo: {last:?}){}",
                    START_TIMEOUT.as_secs(),
                    self.logs()
                )));
            }
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

impl Drop for SlurmCluster {
    fn drop(&mut self) {
        // Jobs first (their steps run under slurmstepd, outside the daemons' process trees).
        if self.daemons.len() == 3 {
            let _ = self
                .command("scancel")
                .args(["--full", "--user=root"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status();
        }
        // slurmd, slurmctld, munged: each asked to stop, then killed if it lingers.
        for (_, child) in self.daemons.iter_mut().rev() {
            terminate(child);
        }
        // The temporary folder goes with `dir`.
    }
}

fn terminate(child: &mut Child) {
    if let Ok(pid) = i32::try_from(child.id()) {
        // SAFETY: `pid` is our own child, not yet waited for, so the id is not reused.
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
    }
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        if let Ok(Some(_)) = child.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
}

struct NodeConfig {
    name: String,
    cpus: u32,
    memory_mb: u64,
}

/// This host as slurmd sees it (`slurmd -C`): its name, CPUs and memory.
fn node_config() -> Result<NodeConfig, String> {
    let out: Output = Command::new(DAEMONS[2])
        .arg("-C")
        .output()
        .map_err(|e| format!("slurmd -C: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let field = |key: &str| {
        text.split_whitespace()
            .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
            .map(str::to_string)
    };
    let (Some(name), Some(cpus), Some(memory)) =
        (field("NodeName"), field("CPUs"), field("RealMemory"))
    else {
        return Err(format!("slurmd -C printed no node line: {}", text.trim()));
    };
    Ok(NodeConfig {
        name,
        cpus: cpus
            .parse()
            .map_err(|_| format!("slurmd -C: CPUs={cpus}"))?,
        // A little below what is there, so the node is never drained for low memory.
        memory_mb: memory
            .parse::<u64>()
            .map_err(|_| format!("slurmd -C: RealMemory={memory}"))?
            .saturating_sub(256)
            .max(1),
    })
}

/// A port nothing listens on now (the OS picks it; a collision after this is unlikely).
fn free_port() -> Result<u16, SkipReason> {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| SkipReason(format!("finding a free port: {e}")))
}

fn is_root() -> bool {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() == 0 }
}

fn set_mode(path: &Path, mode: u32) -> Result<(), SkipReason> {
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .map_err(|e| SkipReason(format!("{}: {e}", path.display())))
}

fn find_in_path(program: &str) -> Option<PathBuf> {
    std::env::var_os("PATH")
        .into_iter()
        .flat_map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .chain([PathBuf::from("/usr/bin"), PathBuf::from("/usr/sbin")])
        .map(|dir| dir.join(program))
        .find(|p| p.is_file())
}
