//! Writing a diagnosis into a directory: report.json, report.md, corrected.json and the plots,
//! all into a temporary sibling directory that is renamed into place at the end, so a failure
//! leaves nothing partial (and an existing directory, with `force`, is replaced only then).

use super::{plots, report_md, DiagnoseError, Diagnosis};
use std::path::{Path, PathBuf};

fn io(path: &Path, e: impl std::fmt::Display) -> DiagnoseError {
    DiagnoseError::Write {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// A sibling of `dir` named `.<name>.<suffix>` (same file system, so `rename` is atomic).
fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    dir.with_file_name(format!(".{name}.{suffix}-{}", std::process::id()))
}

impl Diagnosis {
    /// report.json as written.
    pub fn report_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("the diagnosis serialises") + "\n"
    }

    /// report.md as written (plots linked by file name).
    pub fn report_markdown(&self, plots: &[String]) -> String {
        report_md::markdown(self, plots)
    }

    /// Write the diagnosis into `dir` (created). An existing `dir` is an error unless `force`,
    /// when it is replaced once everything is written. Returns the files written.
    pub fn write(&self, dir: &Path, force: bool) -> Result<Vec<PathBuf>, DiagnoseError> {
        // One critical section: an interrupting signal waits for it (crate::interrupt).
        let _guard = crate::interrupt::output_lock();
        if dir.exists() && !force {
            return Err(io(dir, "exists; pass --force to replace it"));
        }
        if self.corrected.is_null() {
            return Err(DiagnoseError::Corrected(
                "the model file's text is not known: set it with Diagnosis::corrected_from".to_string(),
            ));
        }
        let tmp = sibling(dir, "tmp");
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).map_err(|e| io(&tmp, e))?;
        }
        let result = self.write_into(&tmp);
        let names = match result {
            Ok(n) => n,
            Err(e) => {
                let _ = std::fs::remove_dir_all(&tmp);
                return Err(e);
            }
        };
        if dir.exists() {
            let old = sibling(dir, "old");
            std::fs::rename(dir, &old).map_err(|e| {
                let _ = std::fs::remove_dir_all(&tmp);
                io(dir, e)
            })?;
            if let Err(e) = std::fs::rename(&tmp, dir) {
                let _ = std::fs::rename(&old, dir);
                let _ = std::fs::remove_dir_all(&tmp);
                return Err(io(dir, e));
            }
            let _ = std::fs::remove_dir_all(&old);
        } else {
            std::fs::rename(&tmp, dir).map_err(|e| {
                let _ = std::fs::remove_dir_all(&tmp);
                io(dir, e)
            })?;
        }
        Ok(names.into_iter().map(|n| dir.join(n)).collect())
    }

    fn write_into(&self, tmp: &Path) -> Result<Vec<String>, DiagnoseError> {
        std::fs::create_dir_all(tmp).map_err(|e| io(tmp, e))?;
        let mut names = Vec::new();
        let mut plot_files = Vec::new();
        let bar = tmp.join("rmse_before_after.svg");
        plots::before_after(&self.shrink, &bar).map_err(|e| io(&bar, e))?;
        plot_files.push("rmse_before_after.svg".to_string());
        if let Some(report) = &self.where_report {
            // The "where" plots draw from the report alone; its input series are not kept (see
            // `where_analysis`).
            let input = crate::analysis::WhereInput::default();
            let files = crate::analysis::write_plots(report, &input, tmp).map_err(|e| io(tmp, e))?;
            for f in files {
                if let Some(n) = f.file_name() {
                    plot_files.push(n.to_string_lossy().into_owned());
                }
            }
        }
        let mut put = |name: &str, text: &str| -> Result<(), DiagnoseError> {
            let path = tmp.join(name);
            std::fs::write(&path, text).map_err(|e| io(&path, e))?;
            names.push(name.to_string());
            Ok(())
        };
        put("report.json", &self.report_json())?;
        put("report.md", &self.report_markdown(&plot_files))?;
        let corrected = serde_json::to_string_pretty(&self.corrected).expect("JSON value serialises") + "\n";
        put("corrected.json", &corrected)?;
        names.extend(plot_files);
        Ok(names)
    }
}
