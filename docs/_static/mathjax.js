// MathJax 2.7, served with the site (_static/mathjax/, copied by docs/_hooks/site_assets.py):
// the pages' equations render offline. Only the spans pymdownx.arithmatex marks are typeset.
window.MathJax = {
  tex2jax: {
    inlineMath: [["\\(", "\\)"]],
    displayMath: [["\\[", "\\]"]],
    processEscapes: true,
    processEnvironments: true,
    ignoreClass: ".*",
    processClass: "arithmatex",
  },
  TeX: { extensions: ["AMSmath.js", "AMSsymbols.js"] },
  messageStyle: "none",
  showMathMenu: false,
};

document$.subscribe(() => {
  if (window.MathJax && window.MathJax.Hub) {
    window.MathJax.Hub.Queue(["Typeset", window.MathJax.Hub]);
  }
});
