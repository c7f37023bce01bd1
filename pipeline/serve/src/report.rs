//! The dataset's report as the browser shows it: `report/report.md` rendered to HTML on the
//! server (pulldown-cmark, so the page runs no Markdown code of its own), and the report files a
//! browser may fetch: the report folder's own top-level files and the files `report.md` links to
//! or embeds, nothing else.
//!
//! The HTML is safe to put in the page as it is: raw HTML in the Markdown is shown as text, links
//! and images go to the report's files through the service or to `http(s)` addresses (anything
//! else, `javascript:` included, is shown as its text only), and table alignment is a class, not
//! a `style` attribute the page's Content-Security-Policy would block.

use std::collections::BTreeSet;
use std::path::{Component, Path};

use pulldown_cmark::{CowStr, Event, Options, Parser, Tag, TagEnd};

/// The report's Markdown file, inside the report folder.
pub(crate) const REPORT_MD: &str = "report.md";
/// Largest `report.md` read (bytes): a report is a few tens of kilobytes.
pub(crate) const MAX_REPORT_BYTES: u64 = 4 << 20;

/// A link or image target of the report that names a file of the report folder: a relative path
/// of plain names (no `..`, no scheme, query or fragment).
pub(crate) fn local_target(target: &str) -> Option<&str> {
    if target.is_empty() || target.contains([':', '?', '#', '%', '\\', '\0']) {
        return None;
    }
    let path = Path::new(target);
    path.components()
        .all(|c| matches!(c, Component::Normal(n) if !n.to_string_lossy().starts_with('.')))
        .then_some(target)
}

fn parser(markdown: &str) -> Parser<'_> {
    Parser::new_ext(
        markdown,
        Options::ENABLE_TABLES | Options::ENABLE_STRIKETHROUGH,
    )
}

/// The files `markdown` links to or embeds, in the report folder.
pub(crate) fn referenced(markdown: &str) -> BTreeSet<String> {
    parser(markdown)
        .filter_map(|event| match event {
            Event::Start(Tag::Image { dest_url, .. } | Tag::Link { dest_url, .. }) => {
                local_target(&dest_url).map(str::to_string)
            }
            _ => None,
        })
        .collect()
}

/// An address a rendered link may keep as it is.
fn web_address(target: &str) -> bool {
    let lower = target.to_ascii_lowercase();
    lower.starts_with("https://") || lower.starts_with("http://")
}

/// `markdown` as an HTML fragment; `file_url` gives the service's address of a report file.
pub(crate) fn render(markdown: &str, file_url: &dyn Fn(&str) -> String) -> String {
    // Links and images first: a local target becomes the service's address of the file, a web
    // address stays, anything else is dropped and leaves its text. Raw HTML becomes text.
    let mut kept: Vec<bool> = Vec::new();
    let mut events: Vec<Event<'_>> = Vec::new();
    for event in parser(markdown) {
        match event {
            Event::Start(Tag::Image {
                link_type,
                dest_url,
                title,
                id,
            }) => match local_target(&dest_url) {
                Some(file) => {
                    kept.push(true);
                    events.push(Event::Start(Tag::Image {
                        link_type,
                        dest_url: CowStr::from(file_url(file)),
                        title,
                        id,
                    }));
                }
                None => kept.push(false),
            },
            Event::Start(Tag::Link {
                link_type,
                dest_url,
                title,
                id,
            }) => {
                let target = match local_target(&dest_url) {
                    Some(file) => Some(file_url(file)),
                    None => web_address(&dest_url).then(|| dest_url.to_string()),
                };
                kept.push(target.is_some());
                if let Some(target) = target {
                    events.push(Event::Start(Tag::Link {
                        link_type,
                        dest_url: CowStr::from(target),
                        title,
                        id,
                    }));
                }
            }
            Event::End(end @ (TagEnd::Image | TagEnd::Link)) => {
                if kept.pop().unwrap_or(false) {
                    events.push(Event::End(end));
                }
            }
            Event::Html(html) | Event::InlineHtml(html) => events.push(Event::Text(html)),
            other => events.push(other),
        }
    }
    let mut html = String::new();
    pulldown_cmark::html::push_html(&mut html, figures(events).into_iter());
    for side in ["left", "center", "right"] {
        html = html.replace(
            &format!(" style=\"text-align: {side}\">"),
            &format!(" class=\"{side}\">"),
        );
    }
    html
}

/// Where the image of an image-only paragraph starting at `at` ends (its `End(Image)`), if the
/// paragraph holds one image and nothing else.
fn lone_image(events: &[Event<'_>], at: usize) -> Option<usize> {
    if !matches!(events.get(at), Some(Event::Start(Tag::Paragraph)))
        || !matches!(events.get(at + 1), Some(Event::Start(Tag::Image { .. })))
    {
        return None;
    }
    let end = (at + 2..events.len()).find(|&k| matches!(events[k], Event::End(TagEnd::Image)))?;
    matches!(events.get(end + 1), Some(Event::End(TagEnd::Paragraph))).then_some(end)
}

/// Each paragraph that is one image becomes a `<figure>`; the paragraph right after it (the
/// report writes the caption there) becomes its `<figcaption>`, else the image's text does.
fn figures(events: Vec<Event<'_>>) -> Vec<Event<'_>> {
    let mut out = Vec::with_capacity(events.len());
    let mut at = 0;
    while at < events.len() {
        let Some(end) = lone_image(&events, at) else {
            out.push(events[at].clone());
            at += 1;
            continue;
        };
        out.push(Event::Html(CowStr::from("<figure>")));
        out.extend(events[at + 1..=end].iter().cloned());
        out.push(Event::Html(CowStr::from("<figcaption>")));
        let next = end + 2;
        let caption_end = matches!(events.get(next), Some(Event::Start(Tag::Paragraph)))
            .then(|| {
                (next..events.len()).find(|&k| matches!(events[k], Event::End(TagEnd::Paragraph)))
            })
            .flatten();
        match caption_end {
            Some(close) => {
                out.extend(events[next + 1..close].iter().cloned());
                at = close + 1;
            }
            None => {
                out.extend(
                    events[at + 2..end]
                        .iter()
                        .filter(|e| matches!(e, Event::Text(_) | Event::Code(_)))
                        .cloned(),
                );
                at = end + 2;
            }
        }
        out.push(Event::Html(CowStr::from("</figcaption></figure>")));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn url(file: &str) -> String {
        format!("/datasets/demo/report/file?path={file}")
    }

    #[test]
    fn tables_figures_and_captions_render_and_nothing_runs() {
        let md = "# Title\n\n| a | n |\n|---|---:|\n| x | 1 |\n\n![Clips per type](figures/types.png)\n\n\
                  *Clips per type.* Vector: [figures/types.svg](figures/types.svg).\n\n\
                  <script>alert(1)</script>\n\n[bad](javascript:alert(1)) [out](../secret.txt) \
                  [web](https://example.org/) ![x](https://example.org/x.png)\n";
        let html = render(md, &url);
        assert!(html.contains("<h1>Title</h1>"), "{html}");
        assert!(html.contains("<table>") && html.contains("<td class=\"right\">1</td>"));
        assert!(!html.contains("style="), "{html}");
        assert!(html.contains(
            "<figure><img src=\"/datasets/demo/report/file?path=figures/types.png\" alt=\"Clips per type\" />\
             <figcaption><em>Clips per type.</em> Vector: <a href=\"/datasets/demo/report/file?path=figures/types.svg\">"
        ), "{html}");
        assert!(html.contains("&lt;script&gt;") && !html.contains("<script"));
        assert!(!html.contains("javascript:") && !html.contains("secret.txt\""));
        assert!(html.contains("bad") && html.contains("<a href=\"https://example.org/\">web</a>"));
        // An image from elsewhere is not loaded: its text stays.
        assert!(!html.contains("example.org/x.png"), "{html}");
    }

    #[test]
    fn only_plain_relative_paths_are_report_files() {
        let md = "![a](figures/a.png) [b](b.pdf) [c](../c) [d](/etc/passwd) [e](.hidden) \
                  [f](https://x.org/f.png) [g](figures/%2e%2e/g)";
        let files: Vec<String> = referenced(md).into_iter().collect();
        assert_eq!(files, ["b.pdf", "figures/a.png"]);
    }
}
