//! `gedisim read-granule <request>` (hidden): the child process in which the command line reads
//! one GEDI granule, its shots sent back over stdout (`gedisim::ops::ingest_gedi::child`).

use gedisim::Result;

pub fn read_granule(request: String) -> Result<()> {
    gedisim::ops::ingest_gedi::child::serve(&request, std::io::stdout().lock())
}
