//! The pipeline's report: one HTML file with its SVG plots embedded inline,
//! so that it opens offline in any browser.

/// A report being assembled, section by section.
#[derive(Default)]
pub struct Report {
    sections: Vec<String>,
}

impl Report {
    /// Adds a section with a heading, a paragraph of HTML text and figures
    /// (SVG documents).
    pub fn section(&mut self, heading: &str, text_html: &str, figures: &[String]) {
        let mut html = format!(
            "<section><h2>{}</h2>\n<p>{text_html}</p>\n",
            escape(heading)
        );
        for svg in figures {
            html.push_str("<figure>");
            // An SVG document starts with an XML declaration that is not valid
            // inside HTML; keep only the <svg> element.
            let start = svg.find("<svg").unwrap_or(0);
            html.push_str(&svg[start..]);
            html.push_str("</figure>\n");
        }
        html.push_str("</section>\n");
        self.sections.push(html);
    }

    /// Adds a table with a header row.
    pub fn table(&mut self, heading: &str, header: &[&str], rows: &[Vec<String>]) {
        let mut html = format!("<section><h2>{}</h2>\n<table>\n<tr>", escape(heading));
        for cell in header {
            html.push_str(&format!("<th>{}</th>", escape(cell)));
        }
        html.push_str("</tr>\n");
        for row in rows {
            html.push_str("<tr>");
            for cell in row {
                html.push_str(&format!("<td>{}</td>", escape(cell)));
            }
            html.push_str("</tr>\n");
        }
        html.push_str("</table></section>\n");
        self.sections.push(html);
    }

    /// Adds every section of `other` after this report's.
    pub fn append(&mut self, other: Report) {
        self.sections.extend(other.sections);
    }

    /// The whole document.
    pub fn to_html(&self, title: &str) -> String {
        let mut html = format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
             <title>{0}</title><style>body{{font-family:sans-serif;max-width:70em;margin:2em auto;}}\
             table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:0.2em 0.6em;text-align:right}}\
             figure{{margin:1em 0}}</style></head><body><h1>{0}</h1>\n",
            escape(title)
        );
        for section in &self.sections {
            html.push_str(section);
        }
        html.push_str("</body></html>\n");
        html
    }
}

/// The text with HTML's special characters escaped.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
