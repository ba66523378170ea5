// MathJax's configuration, read before its script (mkdocs.yml, extra_javascript): typeset only
// what pymdownx.arithmatex wrapped (its generic output, \( \) inline and \[ \] display), nothing
// else on the page; SVG output, whose glyphs are inside the script (no font files to fetch).
window.MathJax = {
  tex: {
    inlineMath: [["\\(", "\\)"]],
    displayMath: [["\\[", "\\]"]],
    processEscapes: true,
    processEnvironments: true,
  },
  options: {
    ignoreHtmlClass: ".*|",
    processHtmlClass: "arithmatex",
  },
};
