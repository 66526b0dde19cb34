// eslint for the role pages' JavaScript (app/static/js): the recommended rules, the browser's
// globals, and a few rules that catch what the pages have got wrong before. Run by scripts/test.
import js from '@eslint/js';
import globals from 'globals';

export default [
  {
    ignores: ['app/static/opencv.js', 'app/static/opencv-simd.js', 'app/static/vendor/**'],
  },
  js.configs.recommended,
  {
    files: ['app/static/js/**/*.js'],
    languageOptions: {
      ecmaVersion: 2024,
      sourceType: 'module',
      // roslib.js is a classic script the vehicle page loads before its module.
      globals: { ...globals.browser, ROSLIB: 'readonly' },
    },
    rules: {
      // `x == null` is the one loose comparison kept: null or undefined.
      eqeqeq: ['error', 'always', { null: 'ignore' }],
      'no-var': 'error',
      'prefer-const': 'error',
      'no-unused-vars': ['error', { args: 'after-used', argsIgnorePattern: '^_' }],
      'no-implicit-globals': 'error',
      'no-shadow': 'error',
      // The width ruff holds the Python to; prettier wraps code, this catches comments and strings.
      'max-len': ['error', { code: 100, ignoreUrls: true }],
    },
  },
  {
    // A classic worker (opencv.js is a UMD script loaded with importScripts): its top-level
    // functions are the worker's own global scope, which nothing else shares.
    files: ['app/static/js/worker/vision-worker.js'],
    languageOptions: { sourceType: 'script', globals: { ...globals.worker, cv: 'writable' } },
    rules: { 'no-implicit-globals': 'off' },
  },
  {
    // The tests' Node scripts (the official Foxglove and MCAP clients).
    files: ['tests/**/*.mjs'],
    languageOptions: { ecmaVersion: 2024, sourceType: 'module', globals: globals.node },
    rules: { 'max-len': ['error', { code: 100 }] },
  },
  {
    files: ['eslint.config.js'],
    languageOptions: { sourceType: 'module', globals: globals.node },
  },
];
