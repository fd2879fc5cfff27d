//! One error type for everything that reads scene input: it always names the file, and for
//! TOML the line and column, and says what is wrong.

use std::fmt;
use std::path::{Path, PathBuf};

use miette::{Diagnostic, NamedSource, SourceSpan};

/// A scene, model, texture or point-cloud file that could not be used.
#[derive(Debug, Diagnostic)]
pub struct SceneError {
    /// The file that is wrong.
    pub path: PathBuf,
    /// 1-based line and column in `path`, for text formats that have them (TOML).
    pub location: Option<(usize, usize)>,
    /// What is wrong, in one sentence.
    pub message: String,
    #[source_code]
    pub source_code: Option<NamedSource<String>>,
    #[label("here")]
    pub span: Option<SourceSpan>,
}

impl SceneError {
    pub fn new(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Self { path: path.as_ref().to_path_buf(), location: None, message: message.into(), source_code: None, span: None }
    }

    /// An error at byte range `span` of the text `source` of `path`; line and column are derived.
    pub fn at(path: impl AsRef<Path>, source: &str, span: std::ops::Range<usize>, message: impl Into<String>) -> Self {
        let path = path.as_ref().to_path_buf();
        let start = span.start.min(source.len());
        let line = source[..start].matches('\n').count() + 1;
        let line_start = source[..start].rfind('\n').map_or(0, |i| i + 1);
        let column = source[line_start..start].chars().count() + 1;
        Self {
            location: Some((line, column)),
            message: message.into(),
            source_code: Some(NamedSource::new(path.display().to_string(), source.to_string())),
            span: Some((start, span.end.min(source.len()).saturating_sub(start)).into()),
            path,
        }
    }
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.location {
            Some((l, c)) => write!(f, "{}:{}:{}: {}", self.path.display(), l, c, self.message),
            None => write!(f, "{}: {}", self.path.display(), self.message),
        }
    }
}

impl std::error::Error for SceneError {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn location_is_derived_from_the_span() {
        let src = "a = 1\nbb = 2\n  cc = x\n";
        let at = src.find("x").unwrap();
        let e = SceneError::at("s.toml", src, at..at + 1, "bad value");
        assert_eq!(e.location, Some((3, 8)));
        assert_eq!(e.to_string(), "s.toml:3:8: bad value");
    }
}
