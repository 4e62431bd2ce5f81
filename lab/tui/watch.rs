//! Reload on save, the lab's side: the files a run's code comes from — the graph file, each
//! Python node's script, a Python brain (`--policy FILE.py`) — watched with `notify`
//! (inotify on Linux). A save is told to the engine as [`Control::Reload`], which reads and
//! judges the new code ([`ratelab::session`]'s `reload`).
//!
//! The files follow the run's graph: a reload whose graph runs a script elsewhere (a new
//! node, a script moved to another folder) has that file, and its folder, watched from then
//! on ([`FileWatch::follow`]).
//!
//! The folders are watched, not the files: an editor that saves by writing a new file and
//! renaming it over the old one (vim, most IDEs) replaces the file's inode, which a watch
//! on the file itself would lose. The saves of one file that come within [`SETTLE`] of each
//! other (an editor's write, then its rename) are told once.

use crossbeam_channel::Sender;
use notify::{EventKind, RecursiveMode, Watcher};
use ratelab::graph::GraphSpec;
use ratelab::session::Control;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How long a file must be quiet after a save before it is reloaded.
pub const SETTLE: Duration = Duration::from_millis(50);

/// The files a run's code comes from: the graph file (`None`: the chapter's, compiled in),
/// the graph's Python nodes' scripts, and the brain `policy` when it is a Python file. Each
/// as an absolute path.
pub fn code_files(graph_file: Option<&Path>, graph: &GraphSpec, policy: &str) -> Vec<PathBuf> {
    let mut files: BTreeSet<PathBuf> = BTreeSet::new();
    let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    if let Some(g) = graph_file {
        files.insert(absolute(g));
    }
    for code in graph.nodes.iter().filter_map(|n| n.python.as_ref()) {
        files.insert(absolute(Path::new(&code.script)));
    }
    if let Some((script, _)) = ratelab::python::brain::parse_spec(policy) {
        files.insert(absolute(Path::new(script)));
    }
    files.into_iter().collect()
}

/// Where a run's code comes from: the graph file (`None`: the chapter's, compiled in) and
/// the brain (`--policy`); [`CodeSource::files`] gives the files of a run's graph.
#[derive(Clone, Debug)]
pub struct CodeSource {
    /// The graph file, if any.
    pub graph_file: Option<PathBuf>,
    /// The brain's spec.
    pub policy: String,
}

impl CodeSource {
    /// The files the code of a run of `graph` comes from ([`code_files`]).
    pub fn files(&self, graph: &GraphSpec) -> Vec<PathBuf> {
        code_files(self.graph_file.as_deref(), graph, &self.policy)
    }
}

/// The watch: while it lives, a save of one of its files sends [`Control::Reload`].
pub struct FileWatch {
    watcher: Mutex<notify::RecommendedWatcher>,
    /// The files whose saves are told.
    wanted: Arc<Mutex<BTreeSet<PathBuf>>>,
    /// The folders watched.
    folders: Mutex<BTreeSet<PathBuf>>,
}

impl FileWatch {
    /// Tell the saves of `files` (absolute paths) from now on, instead of those before:
    /// the files of the run that started (a reload's graph may run scripts elsewhere).
    /// Their folders not yet watched are watched; those watched stay (a watch costs one
    /// inotify descriptor, and a file may come back).
    ///
    /// # Errors
    /// The first folder that could not be watched (gone, too many watches): the files there
    /// are not told, the others are (each folder is tried, and one that failed is tried
    /// again on the next call).
    pub fn follow(&self, files: Vec<PathBuf>) -> notify::Result<()> {
        let new: BTreeSet<PathBuf> = folders_of(&files)
            .difference(&lock(&self.folders))
            .cloned()
            .collect();
        *lock(&self.wanted) = files.into_iter().collect();
        let mut watcher = lock(&self.watcher);
        let mut folders = lock(&self.folders);
        let mut failed = Ok(());
        for folder in new {
            match watcher.watch(&folder, RecursiveMode::NonRecursive) {
                Ok(()) => {
                    folders.insert(folder);
                }
                Err(e) => failed = failed.and(Err(e)),
            }
        }
        failed
    }

    /// The folders watched now.
    #[cfg(test)]
    fn folders(&self) -> Vec<PathBuf> {
        lock(&self.folders).iter().cloned().collect()
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The folders `files` are in.
fn folders_of(files: &[PathBuf]) -> BTreeSet<PathBuf> {
    files
        .iter()
        .filter_map(|f| f.parent().map(Path::to_path_buf))
        .collect()
}

/// Watch `files` (absolute paths), telling each save to `to`.
///
/// # Errors
/// The system's watch could not be set up (too many watches, a folder gone): the lab then
/// runs without reloading, and says so.
pub fn watch(files: Vec<PathBuf>, to: Sender<Control>) -> notify::Result<FileWatch> {
    let (saved_tx, saved_rx) = crossbeam_channel::unbounded::<PathBuf>();
    let wanted = Arc::new(Mutex::new(files.iter().cloned().collect::<BTreeSet<_>>()));
    let told = wanted.clone();
    let mut watcher = notify::recommended_watcher(move |event: notify::Result<notify::Event>| {
        let Ok(event) = event else { return };
        if !matches!(event.kind, EventKind::Create(_) | EventKind::Modify(_)) {
            return;
        }
        let wanted = lock(&told);
        for path in event.paths {
            if wanted.contains(&path) {
                let _ = saved_tx.send(path);
            }
        }
    })?;
    let folders = folders_of(&files);
    for folder in &folders {
        watcher.watch(folder, RecursiveMode::NonRecursive)?;
    }
    // One thread settles the saves and tells them; it ends when the watcher goes.
    let _ = std::thread::Builder::new()
        .name("file-watch".into())
        .spawn(move || settle(&saved_rx, &to));
    Ok(FileWatch {
        watcher: Mutex::new(watcher),
        wanted,
        folders: Mutex::new(folders),
    })
}

/// Tell each file saved on `saved` to `to` once it has been quiet for [`SETTLE`].
fn settle(saved: &crossbeam_channel::Receiver<PathBuf>, to: &Sender<Control>) {
    let mut pending: Vec<(PathBuf, Instant)> = Vec::new();
    loop {
        let wait = pending
            .iter()
            .map(|(_, at)| (*at + SETTLE).saturating_duration_since(Instant::now()))
            .min()
            .unwrap_or(Duration::from_secs(3600));
        match saved.recv_timeout(wait) {
            Ok(path) => {
                pending.retain(|(p, _)| *p != path);
                pending.push((path, Instant::now()));
            }
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => return,
        }
        let now = Instant::now();
        let (due, waiting): (Vec<_>, Vec<_>) = pending
            .drain(..)
            .partition(|(_, at)| now.duration_since(*at) >= SETTLE);
        pending = waiting;
        for (file, _) in due {
            if to.send(Control::Reload { file }).is_err() {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_save_is_told_once_and_other_files_are_not() {
        let dir = tempfile::tempdir().unwrap();
        let brain = dir.path().join("brain.py");
        let other = dir.path().join("notes.txt");
        std::fs::write(&brain, "def act(obs):\n    return 0.0\n").unwrap();
        let (tx, rx) = crossbeam_channel::unbounded();
        let files = code_files(None, &GraphSpec::chapter(), brain.to_str().unwrap());
        assert_eq!(files, vec![std::path::absolute(&brain).unwrap()]);
        let _watch = watch(files, tx).unwrap();
        std::fs::write(&other, "x").unwrap();
        // An editor's save: a new file renamed over the old one, then a touch.
        let tmp = dir.path().join(".brain.py.swp");
        std::fs::write(&tmp, "def act(obs):\n    return 0.5\n").unwrap();
        std::fs::rename(&tmp, &brain).unwrap();
        std::fs::write(&brain, "def act(obs):\n    return 0.5\n").unwrap();
        // Told, and only about the brain. Usually once; but a thread descheduled for more
        // than SETTLE between the rename and the write (a loaded machine) is two saves, told
        // twice, so the count is not asserted: every message is the brain's reload.
        let mut told = vec![rx.recv_timeout(Duration::from_secs(5)).unwrap()];
        told.extend(std::iter::from_fn(|| rx.recv_timeout(SETTLE * 6).ok()));
        assert!(
            told.iter()
                .all(|t| matches!(t, Control::Reload { file } if *file == brain)),
            "{told:?}"
        );
    }

    /// A reload's graph runs a script in a folder not watched before: following the new
    /// files watches it, and a save there is told; the file the run no longer uses is not.
    #[test]
    fn the_watch_follows_a_reloaded_graph_into_a_new_folder() {
        let dir = tempfile::tempdir().unwrap();
        let old = dir.path().join("brain.py");
        std::fs::write(&old, "x = 1\n").unwrap();
        std::fs::create_dir(dir.path().join("nodes")).unwrap();
        let new = dir.path().join("nodes").join("policy.py");
        std::fs::write(&new, "x = 1\n").unwrap();
        let (tx, rx) = crossbeam_channel::unbounded();
        let w = watch(vec![old.clone()], tx).unwrap();
        w.follow(vec![new.clone()]).unwrap();
        assert_eq!(
            w.folders(),
            vec![dir.path().to_path_buf(), dir.path().join("nodes")]
        );
        std::fs::write(&old, "x = 2\n").unwrap();
        std::fs::write(&new, "x = 2\n").unwrap();
        let told = rx.recv_timeout(Duration::from_secs(5)).unwrap();
        assert!(
            matches!(&told, Control::Reload { file } if *file == new),
            "{told:?}"
        );
        let more: Vec<Control> = std::iter::from_fn(|| rx.recv_timeout(SETTLE * 6).ok()).collect();
        assert!(
            more.iter()
                .all(|t| matches!(t, Control::Reload { file } if *file == new)),
            "{more:?}"
        );
    }
}
