//! `index.html`: one self-contained page (SVG charts inline, PNG renders as data URIs,
//! no external file or script) with the tables, the Pareto, roll-out and energy charts
//! and the error renders of every experiment.

use std::path::Path;

use base64::Engine;

use super::Charts;
use crate::paper::Table;
use crate::records::ExperimentOutput;
use weft_data::Size;

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Markdown-ish inline code (`x`) to <code>.
fn inline(s: &str) -> String {
    let mut out = String::new();
    for (i, part) in escape(s).split('`').enumerate() {
        if i % 2 == 1 {
            out.push_str(&format!("<code>{part}</code>"));
        } else {
            out.push_str(part);
        }
    }
    out
}

fn table_html(t: &Table) -> String {
    let mut s = format!(
        "<h3>{}</h3>\n<p class=\"cap\">{}</p>\n<div class=\"scroll\"><table>\n<tr>",
        inline(&t.title),
        inline(&t.caption)
    );
    for h in &t.header {
        s.push_str(&format!("<th>{}</th>", inline(h)));
    }
    s.push_str("</tr>\n");
    for r in &t.rows {
        s.push_str("<tr>");
        for c in r {
            // Cells name scenes and methods as `code`, as tables.md prints them.
            s.push_str(&format!("<td>{}</td>", inline(c)));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</table></div>\n");
    s
}

/// The chart `stem.svg` inline, in a `<div>` of `class` ("chart": half the page's width,
/// "family": a figure of many panels at up to its own width).
fn svg_inline(dir: &Path, stem: &str, class: &str) -> crate::Result<String> {
    let svg = std::fs::read_to_string(dir.join(format!("{stem}.svg")))?;
    // Drop any XML prolog; the <svg> element embeds as is.
    let start = svg.find("<svg").unwrap_or(0);
    Ok(format!("<div class=\"{class}\">{}</div>\n", &svg[start..]))
}

fn png_inline(dir: &Path, rel: &str) -> crate::Result<String> {
    let bytes = std::fs::read(dir.join(rel))?;
    let b64 = base64::engine::general_purpose::STANDARD.encode(bytes);
    Ok(format!(
        "<figure><img alt=\"{0}\" src=\"data:image/png;base64,{b64}\"><figcaption>{0}</figcaption></figure>\n",
        escape(rel)
    ))
}

/// What the page opens with.
#[derive(Debug)]
pub struct Summary<'a> {
    pub claims: &'a [super::summary::Claim],
    /// One speed-against-accuracy chart per family: (title, file stem).
    pub families: &'a [(String, String)],
}

fn claims_html(claims: &[super::summary::Claim]) -> String {
    use super::summary::Verdict;
    let mut s = String::from(
        "<div class=\"scroll\"><table class=\"claims\">\n<tr><th>paper</th><th>central claim</th><th>the paper</th><th>ours</th>\
         <th>verdict</th><th>decided by</th></tr>\n",
    );
    for c in claims {
        let class = match c.verdict {
            Verdict::Reproduced => "yes",
            Verdict::NotReproduced => "no",
            Verdict::Undecided { .. } => "undecided",
            Verdict::NotMeasured => "na",
        };
        s.push_str(&format!(
            "<tr><td data-label=\"paper\">{}</td><td data-label=\"central claim\">{}</td><td data-label=\"the paper\">{}</td>\
             <td data-label=\"ours\">{}</td><td data-label=\"verdict\" class=\"{class}\">{}</td>\
             <td data-label=\"decided by\"><code>{}</code></td></tr>\n",
            escape(c.paper),
            escape(c.claim),
            inline(&c.paper_figure),
            inline(&c.ours),
            c.verdict.as_str(),
            escape(&c.command())
        ));
    }
    s.push_str("</table></div>\n");
    s
}

/// The claims a newcomer reads first, and the experiments due for republication.
fn claims_section(summary: &Summary<'_>, outputs: &[ExperimentOutput]) -> String {
    let mut body = String::new();
    body.push_str(
        "<h2 id=\"claims\">The papers' central claims</h2>\n<p class=\"cap\">Each claim is decided from this \
                   report's records by the rule in <code>weft_experiments::report::summary</code>, and only where its \
                   models were trained with at least three seeds — otherwise it is not decided, and the verdict says \
                   which way one seed leans; the command on the right reruns the experiment that decides it.</p>\n",
    );
    body.push_str(&claims_html(summary.claims));
    let stale = super::published::stale(outputs);
    if !stale.is_empty() {
        body.push_str(&format!(
            "<p class=\"cap\">{}</p>\n<ul>\n{}</ul>\n",
            inline(super::STALE_CAPTION),
            stale
                .iter()
                .map(|e| format!("<li>{}</li>\n", inline(e)))
                .collect::<String>()
        ));
    }
    body
}

pub fn page(
    dir: &Path,
    size: Size,
    outputs: &[ExperimentOutput],
    summary: &Summary<'_>,
    tables: &[Table],
    charts: &[Charts],
) -> crate::Result<String> {
    let mut body = String::new();
    body.push_str(&format!(
        "<h1>weft evaluation — {} size</h1>\n<p>Every figure on this page was measured by <code>cargo xtask evaluate \
         --size {}</code>, each experiment in one run of its own ({}), so the time ratios within an experiment compare \
         one machine state; each experiment's command and code version are in <code>PROVENANCE.md</code>. Speed is \
         always shown beside accuracy: time per frame as a ratio to the ground-truth solver timed in the same run, \
         error against a tight reference. The same figures are beside this page in <code>results.json</code> (tidy \
         records), <code>tables.md</code> and <code>plots/</code> (PNG and SVG). Every method's positions beside the \
         reference are written by the evaluation to <code>predictions/</code> in its output directory (its \
         <code>--out</code>); a published report leaves them out for their size.</p>\n",
        size.as_str(),
        size.as_str(),
        super::experiment_times(outputs, |e| format!("<code>{}</code>", escape(e)))
    ));
    // The summary a newcomer reads first, then a table of contents.
    body.push_str(&claims_section(summary, outputs));
    body.push_str(
        "<h2 id=\"contents\">Contents</h2>\n<ul>\n<li><a href=\"#claims\">Claims</a></li>\n\
                   <li><a href=\"#families\">Speed against accuracy, by family</a></li>\n\
                   <li><a href=\"#tables\">The papers' tables beside ours</a></li>\n",
    );
    for o in outputs {
        body.push_str(&format!(
            "<li><a href=\"#experiment-{0}\">Experiment <code>{0}</code></a></li>\n",
            escape(&o.experiment)
        ));
    }
    body.push_str("</ul>\n");
    if !summary.families.is_empty() {
        body.push_str(
            "<h2 id=\"families\">Speed against accuracy, by family</h2>\n<p class=\"cap\">One figure per family, one \
             panel per scene and kind of error: a point is one method's error on that scene against its time per \
             frame over the ground truth's, both from this run. A simulation's error, a reconstruction of a given \
             true frame and a prediction are never on one axis; each figure's header says what its errors \
             measure. Lower left is better; the line is the panel's Pareto front.</p>\n",
        );
        for (_, stem) in summary.families {
            body.push_str(&svg_inline(dir, stem, "family")?);
        }
    }
    body.push_str("<h2 id=\"tables\">Tables</h2>\n");
    for t in tables {
        body.push_str(&table_html(t));
    }
    let ran: Vec<&str> = outputs.iter().map(|o| o.experiment.as_str()).collect();
    let pending = crate::paper::pending(&ran);
    if !pending.is_empty() {
        body.push_str("<h3>Tables that later experiments fill</h3>\n<ul>\n");
        for (what, exp) in pending {
            body.push_str(&format!("<li>{} — experiment <code>{exp}</code></li>\n", escape(what)));
        }
        body.push_str("</ul>\n");
    }
    for (o, c) in outputs.iter().zip(charts) {
        body.push_str(&format!(
            "<h2 id=\"experiment-{0}\">Experiment <code>{0}</code> ({1:.0} s)</h2>\n",
            escape(&o.experiment),
            o.wall_seconds
        ));
        if !c.pareto.is_empty() {
            body.push_str("<h3>Speed against accuracy (Pareto)</h3>\n");
            for (_, stem) in &c.pareto {
                body.push_str(&svg_inline(dir, stem, "chart")?);
            }
        }
        if !c.rollout.is_empty() {
            body.push_str("<h3>Roll-out error against frame</h3>\n");
            for (_, stem) in &c.rollout {
                body.push_str(&svg_inline(dir, stem, "chart")?);
            }
        }
        if !c.energy.is_empty() {
            body.push_str("<h3>Energies</h3>\n");
            for (_, stem) in &c.energy {
                body.push_str(&svg_inline(dir, stem, "chart")?);
            }
        }
        if !c.scatter.is_empty() {
            body.push_str("<h3>Latent spaces</h3>\n");
            for (_, stem) in &c.scatter {
                body.push_str(&svg_inline(dir, stem, "chart")?);
            }
        }
        if !c.lines.is_empty() {
            body.push_str("<h3>Trajectories and extrapolation</h3>\n");
            for (_, stem) in &c.lines {
                body.push_str(&svg_inline(dir, stem, "chart")?);
            }
        }
        if !o.renders.is_empty() {
            body.push_str("<h3>Per-vertex error (one colour scale per scene)</h3>\n<div class=\"renders\">\n");
            for r in &o.renders {
                body.push_str(&png_inline(dir, r)?);
            }
            body.push_str("</div>\n");
        }
        body.push_str("<h3>Notes</h3>\n<ul>\n");
        for n in &o.notes {
            body.push_str(&format!("<li>{}</li>\n", inline(n)));
        }
        for f in &o.failures {
            body.push_str(&format!("<li><b>failed:</b> {}</li>\n", escape(f)));
        }
        body.push_str("</ul>\n");
    }
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n<title>weft evaluation ({})</title>\n\
         <style>\nbody {{ font-family: sans-serif; max-width: 1600px; margin: 2em auto; padding: 0 1em; color: #222; }}\n\
         table {{ border-collapse: collapse; margin-bottom: 1.5em; }}\n\
         th, td {{ border: 1px solid #bbb; padding: 4px 10px; text-align: left; }}\n\
         th {{ background: #eee; }}\n.cap {{ color: #555; max-width: 70em; }}\n\
         .chart {{ display: inline-block; width: 49%; margin: 2px; vertical-align: top; }}\n\
         .chart svg {{ width: 100%; height: auto; }}\n\
         .family {{ margin: 1em 0; overflow-x: auto; }}\n\
         .family svg {{ display: block; max-width: 100%; height: auto; }}\n\
         .scroll {{ overflow-x: auto; }}\n\
         code {{ overflow-wrap: anywhere; }}\n\
         img {{ max-width: 100%; height: auto; }}\n\
         @media (max-width: 900px) {{ body {{ margin: 1em auto; }} .chart {{ width: 100%; }} \
         .family svg {{ max-width: none; }} }}\n\
         @media (max-width: 700px) {{ .claims tr:first-child {{ display: none; }} \
         .claims, .claims tbody, .claims tr, .claims td {{ display: block; }} \
         .claims tr {{ margin-bottom: 1em; border-top: 2px solid #888; }} \
         .claims td::before {{ content: attr(data-label); display: block; font-size: 12px; color: #666; }} }}\n\
         .renders {{ display: flex; flex-wrap: wrap; }}\nfigure {{ margin: 4px; }}\n\
         figcaption {{ font-size: 12px; color: #555; }}\n\
         .claims td.yes {{ background: #d8f0d8; font-weight: bold; }}\n\
         .claims td.no {{ background: #f6d6d6; font-weight: bold; }}\n\
         .claims td.na {{ background: #eee; }}\n\
         .claims td.undecided {{ background: #f6ecc8; }}\n</style>\n</head>\n<body>\n{body}</body>\n</html>\n",
        size.as_str()
    ))
}
