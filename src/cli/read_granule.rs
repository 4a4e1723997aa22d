//! `gedisim read-granule <request|->` (hidden): the child process in which the command line reads
//! one GEDI granule, its shots sent back over stdout (`gedisim::ops::ingest_gedi::child`). The
//! request (JSON) is the argument, or stdin for `-` (the parent's way: an area of thousands of
//! tiles exceeds the length of one argument).

use std::io::Read;

use gedisim::{Error, Result};

pub fn read_granule(request: String) -> Result<()> {
    let request = match request.as_str() {
        "-" => {
            let mut text = String::new();
            std::io::stdin()
                .read_to_string(&mut text)
                .map_err(|e| Error::Usage(format!("read-granule: stdin: {e}")))?;
            text
        }
        _ => request,
    };
    gedisim::ops::ingest_gedi::child::serve(&request, std::io::stdout().lock())
}
