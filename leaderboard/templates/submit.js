var form = document.getElementById('upload'), statusBox = document.getElementById('status');
// The API answers AP as a fraction rounded to 0.001: shown in percent with one decimal.
function ap(v) { return v === null || v === undefined ? 'n/a' : (100 * v).toFixed(1); }
function say(text, failed) { statusBox.textContent = text; statusBox.className = failed ? 'failed' : ''; }
function poll(id, token) {
  fetch('/api/submissions/' + id, {headers: {'Authorization': 'Bearer ' + token}})
    .then(function (r) { return r.json(); })
    .then(function (s) {
      if (s.status === 'scored') {
        say('Submission ' + id + ' scored: AP all ' + ap(s.ap.all) + ' (near ' + ap(s.ap.near) +
            ', mid ' + ap(s.ap.mid) + ', far ' + ap(s.ap.far) + ').');
        var link = document.createElement('a'); link.href = '/'; link.id = 'to-ranking';
        link.textContent = ' See the ranking.'; statusBox.appendChild(link);
      } else if (s.status === 'failed') {
        say('Submission ' + id + ' failed: ' + s.error, true);
      } else {
        say('Submission ' + id + ': ' + s.status + (s.position ? ' (position ' + s.position + ' in the queue)' : '') + '\u2026');
        setTimeout(function () { poll(id, token); }, 1000);
      }
    });
}
form.addEventListener('submit', function (event) {
  event.preventDefault();
  var token = document.getElementById('token').value.trim(), file = document.getElementById('file').files[0];
  if (!file) { say('Choose a predictions file first.', true); return; }
  say('Uploading ' + file.name + '\u2026');
  fetch('/api/submissions', {method: 'POST', body: file,
        headers: {'Authorization': 'Bearer ' + token, 'Content-Type': 'application/json'}})
    .then(function (r) { return r.json().then(function (body) { return [r.status, body]; }); })
    .then(function (answer) {
      var status = answer[0], body = answer[1];
      if (status === 202) { poll(body.id, token); return; }
      say(body.error || ('refused (' + status + ')'), true);
      if (body.problems) {
        var list = document.createElement('ul');
        body.problems.forEach(function (p) { var li = document.createElement('li'); li.textContent = p; list.appendChild(li); });
        statusBox.appendChild(list);
      }
    })
    .catch(function (error) { say('Upload failed: ' + error, true); });
});
