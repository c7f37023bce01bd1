//! Reads captions (one a line) on standard input and prints, for each, a JSON array of its tokens
//! as the caption tagger's perceptron sees them (`motionforge::humanml3d::caption::analyse`):
//! what `tools/train-caption-tagger.py` trains on. A caption that cannot be analysed prints `null`.

use std::io::{BufRead, Write};

fn main() -> std::io::Result<()> {
    let stdin = std::io::stdin();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for line in stdin.lock().lines() {
        let line = line?;
        let analysis = motionforge::humanml3d::caption::analyse(&line).ok();
        let json = serde_json::to_string(&analysis).unwrap_or_else(|_| "null".into());
        writeln!(out, "{json}")?;
    }
    out.flush()
}
