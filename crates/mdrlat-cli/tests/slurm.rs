//! `mdrlat reproduce --executor slurm` through a real one-node Slurm cluster (Debian's
//! slurm-wlm and munge), started on free ports in a temporary folder and stopped by the
//! PIDs it wrote. Without Slurm (or without root, which this set-up needs) the test says why
//! and passes, unless `MDRLAT_REQUIRE_SLURM=1` (set by `.ci/run`) makes that a failure.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const EXE: &str = env!("CARGO_BIN_EXE_mdrlat");

fn slurm_available() -> bool {
    let found = ["munged", "slurmctld", "slurmd", "sbatch", "squeue"].iter().all(|p| {
        Command::new("sh")
            .args(["-c", &format!("command -v {p}")])
            .output()
            .is_ok_and(|o| o.status.success())
    });
    let root = Command::new("id").arg("-u").output().is_ok_and(|o| o.stdout.starts_with(b"0\n"));
    if found && root {
        return true;
    }
    let why = if found { "not running as root" } else { "munged/slurmctld/slurmd/sbatch missing" };
    assert!(
        std::env::var("MDRLAT_REQUIRE_SLURM").as_deref() != Ok("1"),
        "MDRLAT_REQUIRE_SLURM=1 but {why} (see .ci/run for the packages)"
    );
    eprintln!("skipping the Slurm test: {why}");
    false
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// A one-node cluster in a temporary folder; dropped, it stops every daemon it started.
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
}

impl Cluster {
    fn start(dir: &Path) -> Cluster {
        let host = String::from_utf8(
            Command::new("hostname").arg("-s").output().expect("hostname").stdout,
        )
        .expect("utf8")
        .trim()
        .to_string();
        for sub in ["state", "spool"] {
            std::fs::create_dir_all(dir.join(sub)).expect("dir");
        }
        let d = dir.display();
        let cluster = Cluster { dir: dir.to_path_buf(), conf: dir.join("slurm.conf") };
        let munged = Command::new("munged")
            .arg("--force")
            .arg(format!("--socket={d}/munge.sock"))
            .arg(format!("--pid-file={d}/munged.pid"))
            .arg(format!("--log-file={d}/munged.log"))
            .arg(format!("--seed-file={d}/munge.seed"))
            .status()
            .expect("munged");
        assert!(munged.success(), "munged did not start (see {d}/munged.log)");
        let conf = format!(
            "ClusterName=mdrlattest\nSlurmctldHost={host}\nSlurmctldPort={}\nSlurmdPort={}\n\
             AuthType=auth/munge\nAuthInfo=socket={d}/munge.sock\nStateSaveLocation={d}/state\n\
             SlurmdSpoolDir={d}/spool\nSlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/slurmctld.log\nSlurmdLogFile={d}/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nSelectType=select/cons_tres\n\
             SelectTypeParameters=CR_Core\nReturnToService=2\nSlurmUser=root\nSlurmdUser=root\n\
             MpiDefault=none\nJobAcctGatherType=jobacct_gather/none\nMinJobAge=3600\n\
             NodeName={host} CPUs=2 RealMemory=4000 State=UNKNOWN\n\
             PartitionName=debug Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
            free_port(),
            free_port()
        );
        std::fs::write(&cluster.conf, conf).expect("slurm.conf");
        for daemon in ["slurmctld", "slurmd"] {
            let s = cluster.command(daemon).arg("-f").arg(&cluster.conf).status().expect(daemon);
            assert!(s.success(), "{daemon} did not start (see {d}/{daemon}.log)");
        }
        let t = Instant::now();
        loop {
            let o = cluster.command("sinfo").args(["-h", "-o", "%t"]).output().expect("sinfo");
            if String::from_utf8_lossy(&o.stdout).trim() == "idle" {
                break;
            }
            assert!(
                t.elapsed() < Duration::from_secs(30),
                "the node did not become idle (see {d}/slurmd.log)"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        cluster
    }

    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for daemon in ["slurmd", "slurmctld", "munged"] {
            let pid =
                std::fs::read_to_string(self.dir.join(format!("{daemon}.pid"))).unwrap_or_default();
            let pid = pid.trim();
            if !pid.is_empty() && pid.chars().all(|c| c.is_ascii_digit()) {
                let _ = Command::new("kill").args(["-s", "TERM", pid]).status();
                let t = Instant::now();
                while Path::new(&format!("/proc/{pid}")).exists()
                    && t.elapsed() < Duration::from_secs(10)
                {
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        }
    }
}

#[test]
fn the_smoke_sweep_runs_through_a_slurm_cluster() {
    if !slurm_available() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("mdrlat-slurm-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let cluster = Cluster::start(&dir.join("cluster"));
    let out = dir.join("sweep");
    let args = |extra: &[&str]| {
        let mut c = cluster.command(EXE);
        c.args([
            "reproduce",
            "--preset",
            "smoke",
            "--executor",
            "slurm",
            "--cpus-per-task",
            "1",
            "--out",
        ])
        .arg(&out)
        .args(extra);
        c
    };
    let o = args(&["--dry-run", "--partition", "debug", "--slurm-arg=--nice=10"])
        .output()
        .expect("dry run");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let scripts = String::from_utf8_lossy(&o.stdout);
    assert!(
        scripts.contains("#SBATCH --array=0-5") && scripts.contains("#SBATCH --nice=10"),
        "{scripts}"
    );
    assert!(scripts.contains(" reproduce --out "), "{scripts}");
    let o = cluster.command("squeue").args(["-h", "-t", "all"]).output().expect("squeue");
    assert!(o.stdout.is_empty(), "a dry run submits nothing");

    let o = args(&[]).output().expect("submit");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("submitted train: Slurm job"), "{stdout}");
    // Again while those jobs are queued: nothing is queued twice; --wait follows them.
    let o = args(&["--wait"]).output().expect("wait");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.contains("still in Slurm from an earlier submission"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("table2.csv")).expect("table2.csv");
    assert_eq!(csv.lines().count(), 1 + 3 * 7, "{csv}");
    assert!(csv.lines().skip(1).all(|l| l.ends_with(',')), "no cell missing: {csv}");
    assert!(out.join("fig4.png").is_file() && out.join("report.md").is_file());
    // Every array task ran as its own Slurm job (the queue remembers them: MinJobAge).
    let o = cluster
        .command("squeue")
        .args(["-h", "-t", "all", "-o", "%i %T"])
        .output()
        .expect("squeue");
    let queue = String::from_utf8_lossy(&o.stdout);
    assert_eq!(queue.lines().filter(|l| l.ends_with("COMPLETED")).count(), 6 + 7 + 1, "{queue}");

    // Finished: submitting again submits nothing.
    let o = args(&["--wait"]).output().expect("again");
    assert!(o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("every job of the sweep"),
        "nothing resubmitted"
    );
    drop(cluster);
    let _ = std::fs::remove_dir_all(&dir);
}
